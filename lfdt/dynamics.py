"""Forward and inverse dynamics of domain Y (paper eqs. 3-4), fit on Y's random-motion data.

Everything works in the normalised state space of Y (z-score per dimension, statistics of Y's
random data, std floor ``std_floor``): the translator's generator outputs normalised states and
feeds them straight to these models.

* F(y_t, a_t) = y_t + delta_scale * f([y_t, a_t])  predicts the next normalised state;
* F^-1(y_t, y_t+1) = g([y_t, (y_t+1 - y_t) / delta_scale])  predicts the action,

where ``delta_scale`` is the per-dimension standard deviation of normalised one-step changes, so
both nets see and produce quantities of unit scale. Actions are used as recorded, or (``action_scale:
normalised``) z-scored by the random motion's action statistics: the twin's actions are targets a few millimetres
away, and an F^-1 that outputs metres learns them only to about a millimetre.

F's loss is measured in units of one-step change too: in plain normalised units the box, which moves in a
minority of random-motion transitions, would weigh almost nothing next to the joint velocities, and its contact
dynamics would go unlearnt.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from lfdt import data, layout
from lfdt.config import DynamicsConfig
from lfdt.errors import StageError
from lfdt.layout import TaskLayout
from lfdt.nets import Normalizer, batches, check_finite, mlp
from lfdt.optim import Adam


class DynamicsModels(nn.Module):
    """The normaliser of y, the forward model F and the inverse model F^-1, saved as one state dict."""

    def __init__(self, y_dim: int, a_dim: int, hidden: list[int], slope: float = 0.2,
                 normalise_actions: bool = False):
        super().__init__()
        self.y_norm = Normalizer(np.zeros(y_dim), np.ones(y_dim))
        self.register_buffer("delta_scale", torch.ones(y_dim))
        self.f = mlp(y_dim + a_dim, y_dim, hidden, slope)
        self.g = mlp(2 * y_dim, a_dim, hidden, slope)
        # only with action_scale 'normalised', so that models fit on raw actions keep their state dicts unchanged
        self.a_norm = Normalizer(np.zeros(a_dim), np.ones(a_dim)) if normalise_actions else None

    def forward_model(self, y_n: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """F: next normalised state from a normalised state and an action (in the units it was recorded in)."""
        a_in = a if self.a_norm is None else self.a_norm(a)
        return y_n + self.delta_scale * self.f(torch.cat([y_n, a_in], dim=-1))

    def inverse_model(self, y_n: torch.Tensor, y2_n: torch.Tensor) -> torch.Tensor:
        """F^-1: the action (in the units it was recorded in) that takes normalised state y_n to y2_n."""
        out = self.g(torch.cat([y_n, (y2_n - y_n) / self.delta_scale], dim=-1))
        return out if self.a_norm is None else self.a_norm.inverse(out)


ACTION_STD_FLOOR = 1e-4
"""Floor on an action's standard deviation with ``action_scale: normalised`` (0.1 mm for the twin's targets)."""


@dataclass
class RandomY:
    """Y's random-motion transitions as arrays (raw units), with an episode-level split."""

    y: np.ndarray
    a: np.ndarray
    y2: np.ndarray
    episode: np.ndarray
    state_columns: list[str]
    action_columns: list[str]


def load_random_y(path, tl: TaskLayout) -> RandomY:
    """Read Y's random-motion transitions (a file or a recording directory) into arrays, columns by name."""
    cols, acts = tl.state_columns("Y"), tl.action_columns("Y")
    names = ([layout.STATE_PREFIX + c for c in cols] + [layout.ACTION_PREFIX + c for c in acts]
             + [layout.NEXT_STATE_PREFIX + c for c in cols] + ["episode_index"])
    df = data.read_transitions(path, names, kind="random", domain="Y", task=tl.name)
    return RandomY(
        y=df[[layout.STATE_PREFIX + c for c in cols]].to_numpy(np.float32, copy=True),
        a=df[[layout.ACTION_PREFIX + c for c in acts]].to_numpy(np.float32, copy=True),
        y2=df[[layout.NEXT_STATE_PREFIX + c for c in cols]].to_numpy(np.float32, copy=True),
        episode=df["episode_index"].to_numpy(), state_columns=cols, action_columns=acts)


def object_frame_ratios(models: DynamicsModels, y: np.ndarray, a: np.ndarray, y2: np.ndarray, tl: TaskLayout,
                        min_move: float = 1e-4) -> dict[str, float]:
    """F's one-step error on the object, in the object's own frame, as a share of the error of predicting no change
    (the trivial predictor), over the transitions (raw units) in which the object moves by more than ``min_move`` m
    or rad: ``across`` (along the object's first axis: sideways for the box push), ``along`` (its second axis: the
    push direction) and ``angle``. 1 = F knows no more than 'nothing moves'."""
    cols = tl.state_columns("Y")
    ix, iy, ia = (cols.index(c) for c in tl.object_cols)
    moved = (np.abs(y2[:, [ix, iy, ia]] - y[:, [ix, iy, ia]]).max(axis=1) > min_move)
    y, a, y2 = y[moved], a[moved], y2[moved]
    with torch.no_grad():
        pred_n = models.forward_model(models.y_norm(torch.as_tensor(y, dtype=torch.float32)),
                                      torch.as_tensor(a, dtype=torch.float32))
        pred = models.y_norm.inverse(pred_n).numpy().astype(np.float64)
    cos, sin = np.cos(y[:, ia]), np.sin(y[:, ia])

    def frame(d: np.ndarray) -> np.ndarray:  # (N, 3) displacement -> across, along, angle
        return np.stack([d[:, ix] * cos + d[:, iy] * sin, -d[:, ix] * sin + d[:, iy] * cos, d[:, ia]], axis=1)

    err, still = frame(pred - y2), frame(y - y2)
    ratio = (err ** 2).mean(axis=0) / np.maximum((still ** 2).mean(axis=0), 1e-12)
    return {"across": float(ratio[0]), "along": float(ratio[1]), "angle": float(ratio[2]),
            "transitions": int(moved.sum())}


def split_episodes(episode: np.ndarray, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Boolean train/validation masks; whole episodes go to one side."""
    eps = np.unique(episode)
    rng = np.random.default_rng(seed)
    if len(eps) < 2:
        raise StageError(f"{len(eps)} random-motion episode(s) cannot be split into training and validation "
                         "(dynamics.val_fraction); collect more random motion")
    # at least one validation episode, and at least one left to train on
    n_val = min(max(1, int(round(val_fraction * len(eps)))), len(eps) - 1)
    val_eps = rng.choice(eps, size=n_val, replace=False)
    val = np.isin(episode, val_eps)
    return ~val, val


def fit_dynamics(d: RandomY, cfg: DynamicsConfig, log: Callable[[dict, int], None] | None = None,
                 progress=None, device: str | torch.device = "cpu", nets: tuple[str, ...] = ("f", "g"),
                 workers: int = 1) -> tuple[DynamicsModels, dict]:
    """Fit F and F^-1 (L2 losses, eqs. 3-4) on ``device`` on the training episodes; each keeps its parameters of
    lowest held-out error (checked every ``eval_every`` iterations); report held-out errors and ratios. The models
    come back on the CPU.

    ``nets`` fits only some of them (``"f"``: F, ``"g"``: F^-1; the other stays at its initialisation). The two
    share nothing but their minibatch indices, drawn from one generator, so ``workers`` = 2 fits each in a process
    of its own (:func:`lfdt.parallel.run_jobs`) to the same bits as one process fitting both, in about half the
    time; ``log`` then gets the curve once both are done."""
    if workers > 1 and len(nets) == 2:
        return _fit_in_parallel(d, cfg, log, progress, device)
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.torch_threads)
    train, val = split_episodes(d.episode, cfg.val_fraction, cfg.seed)
    models = DynamicsModels(d.y.shape[1], d.a.shape[1], list(cfg.hidden),
                            normalise_actions=cfg.action_scale == "normalised")
    norm = Normalizer.fit(d.y[train], cfg.std_floor, d.state_columns)
    models.y_norm.load_state_dict(norm.state_dict())
    with torch.no_grad():
        y_n = models.y_norm(torch.from_numpy(d.y))
        y2_n = models.y_norm(torch.from_numpy(d.y2))
        delta = (y2_n - y_n)[torch.from_numpy(train)]
        models.delta_scale.copy_(torch.clamp(delta.std(dim=0), min=cfg.std_floor))
    models.to(device)
    y_n, y2_n, a = y_n.to(device), y2_n.to(device), torch.from_numpy(d.a).to(device)
    # minibatch indices are drawn on the CPU (one generator for every device) and moved with the batch
    tr_idx = torch.from_numpy(np.flatnonzero(train))
    va_idx = torch.from_numpy(np.flatnonzero(val)).to(device)
    opt_f = Adam(models.f.parameters(), lr=cfg.learning_rate)
    opt_g = Adam(models.g.parameters(), lr=cfg.learning_rate)
    gen = torch.Generator().manual_seed(cfg.seed)
    a_mean = a[tr_idx.to(device)].mean(dim=0)
    if models.a_norm is not None:
        models.a_norm.mean.copy_(a_mean)
        models.a_norm.std.copy_(torch.clamp(a[tr_idx.to(device)].std(dim=0), min=ACTION_STD_FLOOR))

    def held_out() -> dict:
        with torch.no_grad():
            errs_f, errs_triv, errs_g, errs_mean = [], [], [], []
            for chunk in va_idx.split(65536):
                yv, y2v, av = y_n[chunk], y2_n[chunk], a[chunk]
                errs_f.append(((models.forward_model(yv, av) - y2v) ** 2).mean(dim=0) * len(chunk))
                errs_triv.append(((yv - y2v) ** 2).mean(dim=0) * len(chunk))
                errs_g.append(((models.inverse_model(yv, y2v) - av) ** 2).mean(dim=0) * len(chunk))
                errs_mean.append(((a_mean - av) ** 2).mean(dim=0) * len(chunk))
            n = len(va_idx)
            f_dim, triv_dim = sum(errs_f) / n, sum(errs_triv) / n
            g_dim, mean_dim = sum(errs_g) / n, sum(errs_mean) / n
        return {"forward_mse": float(f_dim.mean()), "forward_trivial_mse": float(triv_dim.mean()),
                "forward_ratio": float(f_dim.mean() / triv_dim.mean()),
                "inverse_mse": float(g_dim.mean()), "inverse_trivial_mse": float(mean_dim.mean()),
                "inverse_ratio": float(g_dim.mean() / mean_dim.mean()),
                "forward_mse_per_column": dict(zip(d.state_columns, f_dim.tolist())),
                "forward_trivial_mse_per_column": dict(zip(d.state_columns, triv_dim.tolist())),
                "inverse_mse_per_column": dict(zip(d.action_columns, g_dim.tolist()))}

    curve = []
    t0 = time.perf_counter()
    run_f, run_g = 0.0, 0.0
    # keep each model at its lowest held-out error (small data sets, e.g. the twin's 3300 samples, overfit)
    best = {"f": (float("inf"), None, 0), "g": (float("inf"), None, 0)}
    for it in range(1, cfg.iterations + 1):
        idx = tr_idx[batches(len(tr_idx), cfg.batch_size, gen)].to(device)
        yb, y2b, ab = y_n[idx], y2_n[idx], a[idx]
        if "f" in nets:
            # in units of one-step change, so the rarely moving box weighs as much as the arms
            loss_f = (((models.forward_model(yb, ab) - y2b) / models.delta_scale) ** 2).mean()
            opt_f.zero_grad(set_to_none=True)
            loss_f.backward()
            opt_f.step()
            run_f += check_finite(loss_f.item(), "F's loss", it)
        if "g" in nets:
            err_g = models.inverse_model(yb, y2b) - ab
            loss_g = ((err_g if models.a_norm is None else err_g / models.a_norm.std) ** 2).mean()
            opt_g.zero_grad(set_to_none=True)
            loss_g.backward()
            opt_g.step()
            run_g += check_finite(loss_g.item(), "F^-1's loss", it)
        if progress is not None:
            progress.update(1)
        if it % cfg.eval_every == 0 or it == cfg.iterations:
            n = cfg.eval_every if it % cfg.eval_every == 0 else it % cfg.eval_every
            ev = held_out()
            point = {"train/forward_loss": run_f / n, "train/inverse_loss": run_g / n,
                     "val/forward_mse": ev["forward_mse"], "val/inverse_mse": ev["inverse_mse"],
                     "val/forward_ratio": ev["forward_ratio"], "val/inverse_ratio": ev["inverse_ratio"]}
            run_f = run_g = 0.0
            for key, err in (("f", ev["forward_mse"]), ("g", ev["inverse_mse"])):
                if key in nets and err < best[key][0]:
                    net = models.f if key == "f" else models.g
                    best[key] = (err, {k: v.clone() for k, v in net.state_dict().items()}, it)
            curve.append({"iteration": it, **point})
            if log:
                log(point, it)
    wall = time.perf_counter() - t0
    for key in nets:
        (models.f if key == "f" else models.g).load_state_dict(best[key][1])
    result = held_out()
    models.cpu()
    result.update({"forward_best_iteration": best["f"][2], "inverse_best_iteration": best["g"][2],
                   "train_transitions": int(train.sum()), "val_transitions": int(val.sum()),
                   "wall_time_s": wall, "iterations_per_s": cfg.iterations / wall, "curve": curve})
    return models.eval(), result


def _fit_job(job: tuple, progress=None) -> tuple[dict, dict]:
    d, cfg, device, net = job
    models, res = fit_dynamics(d, cfg, progress=progress, device=device, nets=(net,))
    return models.state_dict(), res


def _fit_in_parallel(d: RandomY, cfg: DynamicsConfig, log, progress, device) -> tuple[DynamicsModels, dict]:
    """F in one process, F^-1 in another (:func:`fit_dynamics` with ``workers`` = 2), merged."""
    from lfdt.parallel import run_jobs

    (state_f, res_f), (state_g, res_g) = run_jobs(_fit_job, [(d, cfg, str(device), "f"), (d, cfg, str(device), "g")],
                                                  2, total=2 * cfg.iterations, desc="F and F^-1 side by side",
                                                  preload=())  # F's fit logs nothing to MLflow
    models = DynamicsModels(d.y.shape[1], d.a.shape[1], list(cfg.hidden),
                            normalise_actions=cfg.action_scale == "normalised")
    models.load_state_dict({k: (state_g if k.startswith("g.") else state_f)[k] for k in state_f})
    curve = [{k: v for k, v in {**cf, **cg}.items()
              if k == "iteration" or ("forward" in k and k in cf) or ("inverse" in k and k in cg)}
             for cf, cg in zip(res_f["curve"], res_g["curve"])]
    if log:
        for point in curve:
            log({k: v for k, v in point.items() if k != "iteration"}, point["iteration"])
    res = {**{k: v for k, v in res_f.items() if "inverse" not in k},
           **{k: v for k, v in res_g.items() if "inverse" in k},
           "curve": curve, "wall_time_s": max(res_f["wall_time_s"], res_g["wall_time_s"]),
           "forward_best_iteration": res_f["forward_best_iteration"],
           "inverse_best_iteration": res_g["inverse_best_iteration"]}
    res["iterations_per_s"] = cfg.iterations / res["wall_time_s"]
    return models.eval(), res


def load_models(path) -> DynamicsModels:
    """F and F^-1 saved by the fit_dynamics stage (``dynamics.pt`` with its JSON config), in eval mode."""
    from lfdt.nets import load_state, read_config

    cfg = read_config(path)
    missing = [k for k in ("state_columns", "action_columns") if not cfg.get(k)]
    if missing:  # the sizes come from the saved layout, never from a task assumed here
        raise StageError(f"{path}: its config names no {' or '.join(missing)}; refit it (`dvc repro fit_dynamics`)")
    models = DynamicsModels(len(cfg["state_columns"]), len(cfg["action_columns"]), cfg["dynamics"]["hidden"],
                            normalise_actions=cfg["dynamics"].get("action_scale", "raw") == "normalised")
    return load_state(models, path)
