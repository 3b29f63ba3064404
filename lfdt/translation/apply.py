"""Applying a trained translator: its diagnostics, the translation of demonstrations (with BC action labels), the
translated table, and the diagnostics of the translations."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import torch

from lfdt import data, layout
from lfdt.config import TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.layout import TaskLayout
from lfdt.translation.kinematics import Kinematics, end_positions
from lfdt.translation.losses import Losses, normalised
from lfdt.translation.model import MeanTranslator, Translator
from lfdt.translation.transitions import PAIRING_INDEX, Transitions


def translator_diagnostics(tr: Translator, dyn: DynamicsModels, cfg: TranslatorConfig,
                           demos: dict[str, Transitions], random_x: dict[str, Transitions], y_random: np.ndarray,
                           *, tl: TaskLayout, kinematics: Kinematics | None = None,
                           max_random: int = 20_000, seed: int = 0) -> dict:
    """What a trained translator (one member) does, measured on demonstrations (not trained on) and random motion.

    * ``dyn/*``: L_dyn split by the real robot's columns, the missing robot's and the object's;
    * ``D/*``: the discriminator's accuracy on translated demonstrations, on translated X random motion and on
      real Y random motion (0.5 on translated data = D cannot tell them from Y);
    * ``labels/real_robot_rmse``: F^-1's labels for the real robot against its recorded actions (normalised
      torque units; needs the recorded actions in ``demos``);
    * ``fk/missing_robot_ee_error_m`` (and ``real_robot``): an arm's translated end position against the forward
      kinematics of its translated joint angles (needs ``kinematics``).
    """
    gen = torch.Generator().manual_seed(seed)
    losses = Losses(tr, dyn, cfg, tl)
    out: dict[str, float] = {}
    with torch.no_grad():
        x0, x, x2, pidx = normalised(tr, demos)
        h = losses(x0, x, x2, pidx)
        out.update({f"dyn/{k}": v for k, v in losses.dyn_split(h["dyn_sq"], pidx).items()})
        out["dyn/all"] = float(h["dyn"][0])
        out["id/real_robot"] = float(h["id"][0])
        sub = {p: t.subset(torch.randperm(len(t.x), generator=gen)[:max_random // 2].numpy())
               for p, t in random_x.items()}
        xr0, xr, _, pr = normalised(tr, sub)
        yr = tr.generate(xr, pr, xr0 if len(tr.fk_q) else None)
        y_real = dyn.y_norm(torch.as_tensor(y_random[torch.randperm(len(y_random), generator=gen)[:max_random]
                                                       .numpy()]))[None]
        out["D/accuracy_translated_demos"] = float((tr.disc(h["y_hat"]) < 0).float().mean())
        out["D/accuracy_translated_random"] = float((tr.disc(yr) < 0).float().mean())
        out["D/accuracy_real_y"] = float((tr.disc(y_real) > 0).float().mean())
        pidx, y_hat, a_tilde = pidx[0], h["y_hat"][0], h["a_tilde"][0]
        if all(t.a is not None for t in demos.values()):
            n_a = len(tl.arm_action_columns("r1"))
            errs = []
            for p, t in demos.items():
                m = pidx == PAIRING_INDEX[p]
                a_hat = torch.clamp(a_tilde[m], -1.0, 1.0)
                sl = slice(0, n_a) if layout.robot_arm(p) == "r1" else slice(n_a, 2 * n_a)
                errs.append(((a_hat[:, sl] - torch.tensor(t.a)) ** 2).mean(dim=1))
            out["labels/real_robot_rmse"] = float(torch.cat(errs).mean().sqrt())
        if kinematics is not None:
            y_raw = dyn.y_norm.inverse(y_hat)
            for p in layout.PAIRINGS:
                m = pidx == PAIRING_INDEX[p]
                real = layout.robot_arm(p)
                for k, arm in enumerate(kinematics.arms):
                    fk = end_positions(y_raw[m][:, arm.q], torch.as_tensor(arm.links), torch.as_tensor(arm.base))
                    err = torch.linalg.norm(fk - y_raw[m][:, arm.ee], dim=-1)
                    key = "real_robot" if (k == 0) == (real == "r1") else "missing_robot"
                    out.setdefault(f"fk/{key}_ee_error_m", []).append(err)
            for key in ("real_robot", "missing_robot"):
                out[f"fk/{key}_ee_error_m"] = float(torch.cat(out[f"fk/{key}_ee_error_m"]).mean())
    return out


def translate_demos(tr: Translator | MeanTranslator, dyn: DynamicsModels, demos_path: dict[str, str],
                    episodes: dict[str, list[int]], cfg: TranslatorConfig, dt: float, tl: TaskLayout,
                    action_bounds: tuple[float, float] | None = (-1.0, 1.0)) -> pd.DataFrame:
    """Translate every chosen demonstration of both pairings into Y states with BC action labels (raw units).

    ``action_bounds`` clips the inverse model's labels to the action space (None: no clipping).
    """
    y_cols = tl.state_columns("Y")
    a_cols = tl.action_columns("Y")
    frames = []
    ep_out = 0
    for pairing, path in demos_path.items():
        cols = tl.canonical_x_columns(pairing)
        df = data.read_transitions(path, kind="demos", domain=pairing, task=tl.name)
        df = df[df.episode_index.isin(episodes[pairing])]
        robot = layout.robot_arm(pairing)
        for src_ep, g in df.groupby("episode_index", sort=True):
            g = g.sort_values("frame_index")
            x = g[[layout.STATE_PREFIX + c for c in cols]].to_numpy(np.float32)
            x_last = g[[layout.NEXT_STATE_PREFIX + c for c in cols]].to_numpy(np.float32)[-1:]
            y_n = tr.translate(np.concatenate([x, x_last]), pairing)
            with torch.no_grad():
                a_hat = dyn.inverse_model(y_n[:-1], y_n[1:])
                if action_bounds is not None:
                    a_hat = torch.clamp(a_hat, *action_bounds)
                a_hat = a_hat.numpy()
                y = dyn.y_norm.inverse(y_n).numpy()
            if cfg.labels == "recorded_robot":
                rec = g[[layout.ACTION_PREFIX + c for c in tl.arm_action_columns(robot)]].to_numpy()
                n_a = len(tl.arm_action_columns("r1"))
                sl = slice(0, n_a) if robot == "r1" else slice(n_a, 2 * n_a)
                a_hat[:, sl] = rec
            out = pd.DataFrame(y[:-1], columns=[layout.STATE_PREFIX + c for c in y_cols])
            out[[layout.ACTION_PREFIX + c for c in a_cols]] = a_hat
            out[[layout.NEXT_STATE_PREFIX + c for c in y_cols]] = y[1:]
            out.insert(0, "episode_index", ep_out)
            out.insert(1, "frame_index", np.arange(len(g)))
            out.insert(2, "timestamp", np.arange(len(g)) * dt)
            out["source_pairing"] = pairing
            out["source_episode_index"] = int(src_ep)
            frames.append(out)
            ep_out += 1
    return pd.concat(frames, ignore_index=True)


def translated_table(df: pd.DataFrame, metadata: dict, tl: TaskLayout) -> pa.Table:
    """The translated demonstrations as a documented Arrow table (Y layout, same conventions as every dataset)."""
    schema = data.transitions_schema(
        tl.state_columns("Y"), tl.action_columns("Y"),
        extra={"source_pairing": (pa.string(), "pairing of domain X the demonstration was translated from"),
               "source_episode_index": (pa.int64(), "episode_index of the source demonstration in data/demos")},
        metadata=metadata)
    return pa.Table.from_pandas(df[[f.name for f in schema]], schema=schema, preserve_index=False)


def translation_diagnostics(df: pd.DataFrame, demos_path: dict[str, str], episodes: dict[str, list[int]],
                            tl: TaskLayout) -> dict:
    """Compare translated states with the source where they should agree (diagnostics only, never trained on).

    * the real robot's end position, and the object's pose (m, rad): translation should keep them;
    * the translated missing robot's end position vs the human's hand (m): where the push happens;
    * how far across the object, in the object's own frame, the translated missing robot's end, the human's hand and
      the real robot's end are (mean absolute distance from the object's centre line, m), and the missing robot's
      minus the hand's (``missing_minus_hand_across_m``: > 0 pushes further out than the hand did).
    """
    out: dict[str, list[float]] = {"robot_ee_error_m": [], "box_position_error_m": [], "box_yaw_error_rad": [],
                                   "missing_robot_ee_to_hand_m": [], "missing_robot_across_m": [], "hand_across_m": [],
                                   "real_robot_across_m": [], "missing_minus_hand_across_m": []}
    for pairing, path in demos_path.items():
        src = data.read_transitions(path, kind="demos", domain=pairing, task=tl.name)
        src = src[src.episode_index.isin(episodes[pairing])].sort_values(["episode_index", "frame_index"])
        tr = df[df.source_pairing == pairing].sort_values(["source_episode_index", "frame_index"])
        robot = layout.robot_arm(pairing)
        other = "r2" if robot == "r1" else "r1"
        s = layout.STATE_PREFIX

        def xy(frame: pd.DataFrame, arm: str) -> np.ndarray:
            return frame[[layout.STATE_PREFIX + c for c in tl.position_cols[arm]]].to_numpy(float)

        out["robot_ee_error_m"] += np.linalg.norm(xy(tr, robot) - xy(src, robot), axis=1).tolist()
        out["missing_robot_ee_to_hand_m"] += np.linalg.norm(xy(tr, other) - xy(src, "h"), axis=1).tolist()
        box_t = tr[[s + c for c in tl.object_cols]].to_numpy(float)
        box_s = src[[s + c for c in tl.object_cols]].to_numpy(float)
        out["box_position_error_m"] += np.linalg.norm(box_t[:, :2] - box_s[:, :2], axis=1).tolist()
        out["box_yaw_error_rad"] += np.abs(box_t[:, 2] - box_s[:, 2]).tolist()
        missing, hand = np.abs(across(xy(tr, other), box_t)), np.abs(across(xy(src, "h"), box_s))
        out["missing_robot_across_m"] += missing.tolist()
        out["hand_across_m"] += hand.tolist()
        out["real_robot_across_m"] += np.abs(across(xy(tr, robot), box_t)).tolist()
        out["missing_minus_hand_across_m"] += (missing - hand).tolist()
    return {f"diag/{k}": float(np.mean(v)) for k, v in out.items()}


def across(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Where ``points`` (..., 2) lie across an object of planar pose ``pose`` (..., 3: position, angle): their
    coordinate along the object's own first axis, from its centre (m)."""
    rel = points - pose[..., :2]
    return rel[..., 0] * np.cos(pose[..., 2]) + rel[..., 1] * np.sin(pose[..., 2])
