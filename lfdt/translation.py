"""Domain translation X -> Y (paper §III-C): generator G, discriminator D, eqs. 1-6.

G maps a state of domain X, in the canonical order ``[x^Ri, x^H, x^O]`` of its pairing plus a
one-hot of the pairing, to a normalised state of domain Y ``[y^R1, y^R2, y^O]``. D tells real
normalised Y states (from Y's random motion) from G's outputs. The generator's loss is

    lambda_adv * L_adv + lambda_dyn * L_dyn + lambda_id * L_id

with L_dyn = ||F(y_hat_t, F^-1(y_hat_t, y_hat_t+1)) - y_hat_t+1||^2 through the frozen dynamics
models and L_id = ||y_hat^Ri - x^Ri||^2 on the robot that is really there. The ablations are the
same code with a weight at zero (:data:`METHOD_OVERRIDES`).

Normalisation: x^Ri and x^O use Y's statistics of the same columns (so L_id compares like with
like); x^H uses the statistics of the human columns in that pairing's X random data.

Batches: half demonstration transitions, half X random-motion transitions, each half split
evenly between the two pairings; D sees as many real Y states. The human's recorded actions are
never read.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa
import torch
import torch.nn.functional as nnf
from torch import nn

from lfdt import data, layout
from lfdt.config import EnvConfig, TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.envs import BoxPushEnv
from lfdt.layout import BOX_PUSH, TaskLayout
from lfdt.nets import Normalizer, mlp

METHOD_OVERRIDES: dict[str, dict[str, float]] = {
    "lfdt": {},
    "lfdt_no_dyn": {"lambda_dyn": 0.0},
    "lfdt_no_id": {"lambda_id": 0.0},
}
"""Each translator method is the configured loss with these weights overridden."""

PAIRING_INDEX = {p: i for i, p in enumerate(layout.PAIRINGS)}


def method_config(method: str, cfg: TranslatorConfig) -> TranslatorConfig:
    """The translator config of a method (an ablation sets one weight to zero)."""
    if method not in METHOD_OVERRIDES:
        raise ValueError(f"unknown translator method {method!r}; expected one of {sorted(METHOD_OVERRIDES)}")
    return cfg.model_copy(update=METHOD_OVERRIDES[method])


def canonical_x_columns(pairing: str, tl: TaskLayout = BOX_PUSH) -> list[str]:
    """G's input columns of a pairing: the robot that is there, the human stand-in, the object."""
    return tl.canonical_x_columns(pairing)


@dataclass
class Transitions:
    """Consecutive state pairs of one pairing in canonical X order (raw units)."""

    x: np.ndarray
    x2: np.ndarray
    episode: np.ndarray
    frame: np.ndarray


def load_x_transitions(path, pairing: str, episodes: list[int] | None = None,
                       tl: TaskLayout = BOX_PUSH) -> Transitions:
    """State pairs of an X dataset (random or demos), canonical column order, optionally some episodes only."""
    cols = tl.canonical_x_columns(pairing)
    names = ["episode_index", "frame_index"] + [layout.STATE_PREFIX + c for c in cols] + \
        [layout.NEXT_STATE_PREFIX + c for c in cols]
    df = data.read_transitions(path, columns=names)
    if episodes is not None:
        df = df[df.episode_index.isin(episodes)]
    return Transitions(
        x=np.array(df[[layout.STATE_PREFIX + c for c in cols]].to_numpy(np.float32)),
        x2=np.array(df[[layout.NEXT_STATE_PREFIX + c for c in cols]].to_numpy(np.float32)),
        episode=df.episode_index.to_numpy(), frame=df.frame_index.to_numpy())


class Translator(nn.Module):
    """G, D and the X normalisers of both pairings, saved as one state dict."""

    def __init__(self, hidden: list[int], tl: TaskLayout = BOX_PUSH, slope: float = 0.2):
        super().__init__()
        x_dim = len(tl.canonical_x_columns("R1H"))
        y_dim = len(tl.state_columns("Y"))
        self.x_norms = nn.ModuleDict({p: Normalizer(np.zeros(x_dim), np.ones(x_dim)) for p in layout.PAIRINGS})
        self.G = mlp(x_dim + len(layout.PAIRINGS), y_dim, hidden, slope)
        self.D = mlp(y_dim, 1, hidden, slope)
        # skip connections (see skip_pairs): y_n[j] += x_n[src[j]] * scale[j] + offset[j] where src[j] >= 0
        n_p = len(layout.PAIRINGS)
        self.register_buffer("skip_src", torch.full((n_p, y_dim), -1, dtype=torch.long))
        self.register_buffer("skip_scale", torch.zeros(n_p, y_dim))
        self.register_buffer("skip_offset", torch.zeros(n_p, y_dim))
        # 1 where G's own output counts, 0 where the state is copied from x (object: "copy")
        self.register_buffer("g_mask", torch.ones(y_dim))

    def generate(self, x_n: torch.Tensor, pairing_idx: torch.Tensor) -> torch.Tensor:
        """y_hat (normalised Y state) from normalised canonical x and the pairing index."""
        onehot = nnf.one_hot(pairing_idx, len(layout.PAIRINGS)).to(x_n.dtype)
        y = self.G(torch.cat([x_n, onehot], dim=-1)) * self.g_mask
        src = self.skip_src[pairing_idx]
        has = src >= 0
        if bool(has.any()):
            copied = torch.gather(x_n, 1, src.clamp(min=0))
            y = y + torch.where(has, copied * self.skip_scale[pairing_idx] + self.skip_offset[pairing_idx],
                                torch.zeros_like(y))
        return y

    def translate(self, x: np.ndarray, pairing: str) -> torch.Tensor:
        """Normalised y_hat for raw canonical x of one pairing (no gradient)."""
        with torch.no_grad():
            xt = torch.as_tensor(x, dtype=torch.float32)
            idx = torch.full((len(xt),), PAIRING_INDEX[pairing], dtype=torch.long)
            return self.generate(self.x_norms[pairing](xt), idx)


def skip_pairs(pairing: str, object_mode: str, hand_skip: bool, tl: TaskLayout = BOX_PUSH) -> list[tuple[str, str]]:
    """(x column, y column) pairs G adds to its output: quantities observed in the same world frame in X and Y.

    object_mode 'correct' or 'copy': the object's pose (the same object, seen alike in both domains);
    hand_skip: the human's hand position -> the end position of the robot that will stand in its place.
    """
    pairs = []
    if object_mode in ("correct", "copy"):
        pairs += [(c, c) for c in tl.object_cols]
    if hand_skip:
        missing = "r2" if layout.robot_arm(pairing) == "r1" else "r1"
        pairs += list(zip(tl.position_cols["h"], tl.position_cols[missing]))
    return pairs


def fit_x_normalizers(translator: Translator, dyn: DynamicsModels, random_x: dict[str, Transitions],
                      std_floor: float, object_mode: str = "translate", hand_skip: bool = False,
                      tl: TaskLayout = BOX_PUSH) -> None:
    """Robot and object columns take Y's statistics; the human's come from that pairing's X random data.

    Also sets the skip connections, converting each copied x column from its normalisation to its y column's.
    """
    y_cols = tl.state_columns("Y")
    for pairing, tr in random_x.items():
        cols = tl.canonical_x_columns(pairing)
        own = Normalizer.fit(tr.x, std_floor)
        mean, std = own.mean.clone(), own.std.clone()
        for i, c in enumerate(cols):
            if not c.startswith("h."):
                j = y_cols.index(c)
                mean[i], std[i] = dyn.y_norm.mean[j], dyn.y_norm.std[j]
        translator.x_norms[pairing].mean.copy_(mean)
        translator.x_norms[pairing].std.copy_(std)
        k = PAIRING_INDEX[pairing]
        for xc, yc in skip_pairs(pairing, object_mode, hand_skip, tl):
            i, j = cols.index(xc), y_cols.index(yc)
            # x_raw = x_n * std_x + mean_x; y_n = (x_raw - mean_y) / std_y
            translator.skip_src[k, j] = i
            translator.skip_scale[k, j] = std[i] / dyn.y_norm.std[j]
            translator.skip_offset[k, j] = (mean[i] - dyn.y_norm.mean[j]) / dyn.y_norm.std[j]
    if object_mode == "copy":
        for c in tl.object_cols:
            translator.g_mask[y_cols.index(c)] = 0.0


def _gan_losses(kind: str):
    if kind == "bce":
        def d_loss(real, fake):
            return (nnf.binary_cross_entropy_with_logits(real, torch.ones_like(real))
                    + nnf.binary_cross_entropy_with_logits(fake, torch.zeros_like(fake)))

        def g_loss(fake):
            return nnf.binary_cross_entropy_with_logits(fake, torch.ones_like(fake))
    else:
        def d_loss(real, fake):
            return ((real - 1) ** 2).mean() + (fake ** 2).mean()

        def g_loss(fake):
            return ((fake - 1) ** 2).mean()
    return d_loss, g_loss


class _Sampler:
    """Draws the index sets of one batch from per-pairing tensors."""

    def __init__(self, sets: dict[str, Transitions], translator: Translator, gen: torch.Generator):
        self.gen = gen
        self.x, self.x2, self.n = {}, {}, {}
        for p, tr in sets.items():
            norm = translator.x_norms[p]
            with torch.no_grad():
                self.x[p] = norm(torch.as_tensor(tr.x))
                self.x2[p] = norm(torch.as_tensor(tr.x2))
            self.n[p] = len(tr.x)

    def sample(self, per_pairing: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        xs, x2s, ps = [], [], []
        for p in layout.PAIRINGS:
            idx = torch.randint(0, self.n[p], (per_pairing,), generator=self.gen)
            xs.append(self.x[p][idx])
            x2s.append(self.x2[p][idx])
            ps.append(torch.full((per_pairing,), PAIRING_INDEX[p], dtype=torch.long))
        return torch.cat(xs), torch.cat(x2s), torch.cat(ps)


def train_translator(demos: dict[str, Transitions], random_x: dict[str, Transitions], y_random: np.ndarray,
                     dyn: DynamicsModels, cfg: TranslatorConfig, seed: int, std_floor: float = 1e-2,
                     log: Callable[[dict, int], None] | None = None, progress=None,
                     tl: TaskLayout = BOX_PUSH) -> tuple[Translator, dict]:
    """Train G and D with eq. 6 (frozen F, F^-1). Returns the translator and training statistics."""
    torch.manual_seed(seed)
    torch.set_num_threads(cfg.torch_threads)
    gen = torch.Generator().manual_seed(seed)
    dyn = dyn.eval()
    for prm in dyn.parameters():
        prm.requires_grad_(False)
    tr = Translator(list(cfg.hidden), tl)
    fit_x_normalizers(tr, dyn, random_x, std_floor, cfg.object, cfg.hand_skip, tl)
    demo_s, rand_s = _Sampler(demos, tr, gen), _Sampler(random_x, tr, gen)
    with torch.no_grad():
        y_real_all = dyn.y_norm(torch.as_tensor(y_random))
    opt_g = torch.optim.Adam(tr.G.parameters(), lr=cfg.learning_rate, betas=(0.5, 0.999))
    opt_d = torch.optim.Adam(tr.D.parameters(), lr=cfg.learning_rate, betas=(0.5, 0.999))
    d_loss_fn, g_loss_fn = _gan_losses(cfg.gan_loss)
    quarter = max(1, cfg.batch_size // 4)
    robot_mask = torch.zeros(len(layout.PAIRINGS), len(tl.state_columns("Y")), dtype=torch.bool)
    for p, i in PAIRING_INDEX.items():
        robot_mask[i, tl.robot_y_slice(p)] = True
    n_robot = len(tl.arm_cols["r1"])
    history: list[torch.Tensor] = []
    dyn_scale = dyn.delta_scale if cfg.dyn_scale == "delta" else torch.ones_like(dyn.delta_scale)
    sums: dict[str, float] = {}
    curve = []
    t0 = time.perf_counter()
    for it in range(1, cfg.iterations + 1):
        xd, xd2, pd_ = demo_s.sample(quarter)
        xr, xr2, pr = rand_s.sample(quarter)
        x, x2, pidx = torch.cat([xd, xr]), torch.cat([xd2, xr2]), torch.cat([pd_, pr])
        y_hat = tr.generate(x, pidx)
        y_hat2 = tr.generate(x2, pidx)
        # --- D step (fakes detached; optionally mixed with a pool of past fakes)
        fake = y_hat.detach()
        if cfg.history_size:
            history.append(fake)
            pool = torch.cat(history)[-cfg.history_size:]
            history = [pool]
            fake = pool[torch.randint(0, len(pool), (len(y_hat),), generator=gen)]
        y_real = y_real_all[torch.randint(0, len(y_real_all), (len(y_hat),), generator=gen)]
        d_real, d_fake = tr.D(y_real), tr.D(fake)
        l_d = d_loss_fn(d_real, d_fake)
        opt_d.zero_grad(set_to_none=True)
        l_d.backward()
        opt_d.step()
        # --- G step
        l_adv = g_loss_fn(tr.D(y_hat))
        a_tilde = dyn.inverse_model(y_hat, y_hat2)
        y_tilde = dyn.forward_model(y_hat, a_tilde)
        l_dyn = (((y_tilde - y_hat2) / dyn_scale) ** 2).mean()
        x_robot = x[:, :n_robot]
        y_robot = y_hat[robot_mask[pidx]].view(-1, n_robot)
        l_id = ((y_robot - x_robot) ** 2).mean()
        loss = cfg.lambda_adv * l_adv + cfg.lambda_dyn * l_dyn + cfg.lambda_id * l_id
        opt_g.zero_grad(set_to_none=True)
        loss.backward()
        opt_g.step()
        with torch.no_grad():
            acc = 0.5 * ((d_real > 0).float().mean() + (d_fake < 0).float().mean())
        for k, v in (("loss/D", l_d), ("loss/adv", l_adv), ("loss/dyn", l_dyn), ("loss/id", l_id),
                     ("loss/G_total", loss), ("D/accuracy", acc)):
            sums[k] = sums.get(k, 0.0) + v.item()
        if progress is not None:
            progress.update(1)
        if it % cfg.log_every == 0 or it == cfg.iterations:
            n = cfg.log_every if it % cfg.log_every == 0 else it % cfg.log_every
            point = {k: v / n for k, v in sums.items()}
            sums = {}
            curve.append({"iteration": it, **point})
            if log:
                log(point, it)
    wall = time.perf_counter() - t0
    return tr.eval(), {"wall_time_s": wall, "iterations_per_s": cfg.iterations / wall, "curve": curve,
                       "final": curve[-1] if curve else {}}


def translate_demos(tr: Translator, dyn: DynamicsModels, demos_path: dict[str, str], episodes: dict[str, list[int]],
                    cfg: TranslatorConfig, dt: float, tl: TaskLayout = BOX_PUSH,
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
        df = data.read_transitions(path)
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


def translated_table(df: pd.DataFrame, metadata: dict, tl: TaskLayout = BOX_PUSH) -> pa.Table:
    """The translated demonstrations as a documented Arrow table (Y layout, same conventions as every dataset)."""
    schema = data.transitions_schema(
        tl.state_columns("Y"), tl.action_columns("Y"),
        extra={"source_pairing": (pa.string(), "pairing of domain X the demonstration was translated from"),
               "source_episode_index": (pa.int64(), "episode_index of the source demonstration in data/demos")},
        metadata=metadata)
    return pa.Table.from_pandas(df[[f.name for f in schema]], schema=schema, preserve_index=False)


def replay_check(df: pd.DataFrame, env_cfg: EnvConfig) -> dict:
    """Replay each translated demonstration's action labels in the real Y environment from its first state.

    Returns how far the replayed box ends from the translated box's final pose (mean position error in m,
    mean absolute yaw error in rad) and how often the replay solves the task: a physical-consistency check.
    """
    env = BoxPushEnv("Y", env_cfg)
    cols = layout.state_columns("Y")
    q_cols = [c for c in cols if ".q" in c]
    dq_cols = [c for c in cols if ".dq" in c]
    a_cols = [layout.ACTION_PREFIX + c for c in layout.action_columns("Y")]
    pos_err, yaw_err, solved = [], [], []
    for _, g in df.groupby("episode_index", sort=True):
        g = g.sort_values("frame_index")
        first = g.iloc[0]
        qpos = np.concatenate([[first[layout.STATE_PREFIX + c] for c in q_cols],
                               [first[layout.STATE_PREFIX + c] for c in layout.OBJECT_COLUMNS]])
        qvel = np.concatenate([[first[layout.STATE_PREFIX + c] for c in dq_cols], np.zeros(3)])
        env.reset(seed=0)
        env.set_state(qpos, qvel)
        success = False
        for a in g[a_cols].to_numpy():
            _, _, term, _, info = env.step(a)
            success = success or term
        final = env.data.qpos[env.scene.box_qpos]
        target = g.iloc[-1][[layout.NEXT_STATE_PREFIX + c for c in layout.OBJECT_COLUMNS]].to_numpy(float)
        pos_err.append(float(np.linalg.norm(final[:2] - target[:2])))
        yaw_err.append(float(abs((final[2] - target[2] + np.pi) % (2 * np.pi) - np.pi)))
        solved.append(success)
    return {"replay_box_position_error_m": float(np.mean(pos_err)), "replay_box_yaw_error_rad": float(np.mean(yaw_err)),
            "replay_success_rate": float(np.mean(solved)), "replayed_demos": len(pos_err)}


def translation_diagnostics(df: pd.DataFrame, demos_path: dict[str, str], episodes: dict[str, list[int]],
                            tl: TaskLayout = BOX_PUSH) -> dict:
    """Compare translated states with the source where they should agree (diagnostics only, never trained on).

    * the real robot's end position, and the object's pose (m, rad): translation should keep them;
    * the translated missing robot's end position vs the human's hand (m): where the push happens.
    """
    out: dict[str, list[float]] = {"robot_ee_error_m": [], "box_position_error_m": [], "box_yaw_error_rad": [],
                                   "missing_robot_ee_to_hand_m": []}
    for pairing, path in demos_path.items():
        src = data.read_transitions(path)
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
    return {f"diag/{k}": float(np.mean(v)) for k, v in out.items()}
