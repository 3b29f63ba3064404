"""Training: the translators of a stack of members (G and D with eq. 6 through frozen F, F^-1), each keeping its G of
the lowest held-out translation loss."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from lfdt import layout
from lfdt.config import TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.layout import TaskLayout
from lfdt.nets import check_finite, softplus
from lfdt.optim import Adam
from lfdt.translation.checkpoint import Checkpoint, run_key
from lfdt.translation.kinematics import Kinematics
from lfdt.translation.losses import Losses, normalised
from lfdt.translation.model import Translator, fit_x_normalizers
from lfdt.translation.transitions import PAIRING_INDEX, Transitions


def _gan_losses(kind: str):
    """(D's loss, G's adversarial loss) per member, from logits ``(n, batch, 1)``: shape ``(n,)``.

    'bce' is eq. 1's binary cross-entropy with logits, written as softplus (-log sigmoid(l) = softplus(-l)):
    :func:`lfdt.nets.softplus` gives every element the same code wherever it sits in a stack of members."""
    if kind == "bce":
        def d_loss(real, fake):
            return softplus(-real).mean(dim=(1, 2)) + softplus(fake).mean(dim=(1, 2))

        def g_loss(fake):
            return softplus(-fake).mean(dim=(1, 2))
    else:
        def d_loss(real, fake):
            return ((real - 1) ** 2).mean(dim=(1, 2)) + (fake ** 2).mean(dim=(1, 2))

        def g_loss(fake):
            return ((fake - 1) ** 2).mean(dim=(1, 2))
    return d_loss, g_loss


class _Sampler:
    """Draws the transitions of one member's batches from per-pairing tensors, with the member's generator."""

    def __init__(self, sets: dict[str, Transitions], translator: Translator, gen: torch.Generator,
                 device: str | torch.device = "cpu", cache: dict | None = None):
        self.gen, self.device = gen, device
        self.x, self.x2, self.x0, self.n = {}, {}, {}, {}
        for p, tr in sets.items():
            key = (id(tr), p)
            if cache is not None and key in cache:  # members sharing a data set share its tensors
                self.x[p], self.x2[p], self.x0[p] = cache[key]
            else:
                norm = translator.x_norms[p]
                with torch.no_grad():
                    self.x[p] = norm(torch.as_tensor(tr.x, device=device))
                    self.x2[p] = norm(torch.as_tensor(tr.x2, device=device))
                    self.x0[p] = self.x[p] if tr.x_prev is None else norm(torch.as_tensor(tr.x_prev, device=device))
                if cache is not None:
                    cache[key] = (self.x[p], self.x2[p], self.x0[p])
            self.n[p] = len(tr.x)

    def sample(self, per_pairing: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(x_prev, x, x2, pairing index) of ``per_pairing`` random transitions of each pairing."""
        x0s, xs, x2s, ps = [], [], [], []
        for p in layout.PAIRINGS:
            # drawn on the CPU, so a seed draws the same batches on every device
            idx = torch.randint(0, self.n[p], (per_pairing,), generator=self.gen).to(self.device)
            x0s.append(self.x0[p][idx])
            xs.append(self.x[p][idx])
            x2s.append(self.x2[p][idx])
            ps.append(torch.full((per_pairing,), PAIRING_INDEX[p], dtype=torch.long, device=self.device))
        return torch.cat(x0s), torch.cat(xs), torch.cat(x2s), torch.cat(ps)


@dataclass
class Member:
    """One translator of a stack: its demonstrations, those held out for selection, and its seed."""

    demos: dict[str, Transitions]
    """The demonstrations G trains on, per pairing."""
    seed: int
    """Initialisation and minibatch seed."""
    held_out: dict[str, Transitions] | None = None
    """Demonstrations G never trains on; its parameters of the lowest translation loss on them are kept."""


def train_translators(members: list[Member], random_x: dict[str, Transitions], y_random: np.ndarray,
                      dyn: DynamicsModels, cfg: TranslatorConfig, std_floor: float = 1e-2,
                      logs: list[Callable[[dict, int], None] | None] | None = None, progress=None,
                      *, tl: TaskLayout, kinematics: Kinematics | None = None, device: str | torch.device = "cpu",
                      checkpoint_dir: str | Path | None = None) -> tuple[list[Translator], list[dict]]:
    """Train the translators of several members of one configuration (seeds, restarts) as one stacked model: G and D
    with eq. 6 (frozen F, F^-1) on ``device``. Each member has its own initialisation, demonstrations, minibatches
    and checkpoint; its result is the same bits whether it trains alone or in any stack (a test checks). Returns one
    translator (a stack of one, on the CPU) and one dict of training statistics per member.

    Every ``cfg.select_every`` iterations a member's translation loss on its held-out demonstrations is measured and
    it keeps its G of the lowest value (without them, the last iterate). ``kinematics`` is required with
    ``cfg.kinematics == 'forward'`` (the arms whose end columns G does not output).

    With ``checkpoint_dir`` the whole training state is saved there every ``cfg.select_every`` iterations, and a
    checkpoint of the same run found there (:mod:`lfdt.translation.checkpoint`) is resumed: the same bits as a run
    never stopped. The caller removes it once the translators are saved.
    """
    if not members:
        raise ValueError("train_translators needs at least one member")
    torch.set_num_threads(cfg.torch_threads)
    dyn = dyn.eval()
    for prm in dyn.parameters():
        prm.requires_grad_(False)
    if cfg.kinematics == "forward" and kinematics is None:
        raise ValueError("translator.kinematics = 'forward' needs the arms' kinematics; this task has none")
    gens = [torch.Generator().manual_seed(m.seed) for m in members]
    tr = new_translator(cfg, tl, kinematics, n=len(members), generators=gens)
    tr.y_mean.copy_(dyn.y_norm.mean)
    tr.y_std.copy_(dyn.y_norm.std)
    fit_x_normalizers(tr, dyn, random_x, std_floor, cfg.object, cfg.hand_skip, tl=tl)
    checkpoint = None
    if checkpoint_dir is not None:
        checkpoint = Checkpoint(checkpoint_dir, run_key(cfg, [m.seed for m in members], [m.demos for m in members],
                                                        [m.held_out for m in members], random_x, y_random,
                                                        [tr, dyn], str(device)))
    try:
        tr.to(device)
        dyn.to(device)
        return _train_stack(tr, dyn, members, random_x, y_random, cfg, gens, logs or [None] * len(members),
                            progress, tl, device, checkpoint)
    finally:
        dyn.cpu()


def new_translator(cfg: TranslatorConfig, tl: TaskLayout, kinematics: Kinematics | None = None, n: int = 1,
                   generators: list[torch.Generator] | None = None) -> Translator:
    """An untrained translator of ``cfg`` (a stack of ``n``): what :func:`train_translators` trains, and what a
    saved one loads into (:func:`lfdt.nets.load_state`)."""
    y_cols = tl.state_columns("Y")
    d_cols = None if cfg.disc_input == "state" else [i for i, c in enumerate(y_cols) if c not in tl.object_cols]
    return Translator(list(cfg.hidden), tl, kinematics=kinematics if cfg.kinematics == "forward" else None,
                      d_cols=d_cols, hand_offset=cfg.hand_offset, n=n, generators=generators)


def train_translator(demos: dict[str, Transitions], random_x: dict[str, Transitions], y_random: np.ndarray,
                     dyn: DynamicsModels, cfg: TranslatorConfig, seed: int, std_floor: float = 1e-2,
                     log: Callable[[dict, int], None] | None = None, progress=None,
                     *, tl: TaskLayout, kinematics: Kinematics | None = None,
                     held_out: dict[str, Transitions] | None = None, device: str | torch.device = "cpu"
                     ) -> tuple[Translator, dict]:
    """One translator (:func:`train_translators` with one member). Returns it (on the CPU) and its statistics."""
    trs, stats = train_translators([Member(demos, seed, held_out)], random_x, y_random, dyn, cfg, std_floor,
                                   [log], progress, tl=tl, kinematics=kinematics, device=device)
    return trs[0], stats[0]


def lr_factor(kind: str, it: int, iterations: int) -> float:
    """The learning rate's share at iteration ``it`` (1-based) of ``iterations`` (``translator.lr_decay``)."""
    frac = (it - 1) / iterations
    if kind == "cosine":
        return 0.5 * (1.0 + math.cos(math.pi * frac))
    if kind == "linear":
        return 1.0 - frac
    return 1.0


def weighted_sum(terms: list[tuple[float, torch.Tensor]]) -> torch.Tensor:
    """The sum of ``weight * loss`` over the terms, in order, leaving out those of weight 0.

    A term of weight 0 would still send its zero gradient back through everything it was made of (L_dyn: through F and
    F^-1, 18 % of lfdt_no_dyn's training time); leaving it out changes no bit of the loss or of a gradient, as adding
    0 * l (l finite) to a float changes nothing but the sign of a zero."""
    kept = [(w, loss) for w, loss in terms if w != 0]
    if not kept:
        raise ValueError("every term of the translator's loss has weight 0: nothing to train")
    total = kept[0][0] * kept[0][1]
    for w, loss in kept[1:]:
        total = total + w * loss
    return total


def _train_stack(tr: Translator, dyn: DynamicsModels, members: list[Member], random_x: dict[str, Transitions],
                 y_random: np.ndarray, cfg: TranslatorConfig, gens: list[torch.Generator],
                 logs: list[Callable[[dict, int], None] | None], progress, tl: TaskLayout,
                 device: str | torch.device, checkpoint: Checkpoint | None = None
                 ) -> tuple[list[Translator], list[dict]]:
    """The training loop of :func:`train_translators`, with ``tr`` and ``dyn`` on ``device``."""
    n = len(members)
    cache: dict = {}
    demo_s = [_Sampler(m.demos, tr, g, device, cache) for m, g in zip(members, gens)]
    rand_s = [_Sampler(random_x, tr, g, device, cache) for g in gens]
    with torch.no_grad():
        y_real_all = dyn.y_norm(torch.as_tensor(y_random, device=device))
    opt_g = Adam(tr.generator_parameters(), lr=cfg.learning_rate, betas=(0.5, 0.999))
    opt_d = Adam(tr.D.parameters(), lr=cfg.learning_rate * cfg.d_lr_scale, betas=(0.5, 0.999))
    d_loss_fn, g_loss_fn = _gan_losses(cfg.gan_loss)
    losses = Losses(tr, dyn, cfg, tl)
    quarter = max(1, cfg.batch_size // 4)
    holds = [normalised(tr, m.held_out, device) if m.held_out else None for m in members]
    y_dim = len(tl.state_columns("Y"))
    pools = [torch.empty(0, y_dim, device=device) for _ in members]
    best: list[tuple[float, dict | None, int]] = [(float("inf"), None, 0)] * n
    sums = [dict() for _ in members]
    curves: list[list[dict]] = [[] for _ in members]
    # the sideways term joins the curve only where it is on (translators without it keep their curves of before)
    curve_keys = ("loss/D", "loss/adv", "loss/dyn", "loss/id", "loss/hand", "loss/G_total", "D/accuracy",
                  *(("loss/side",) if cfg.lambda_side else ()))
    start, wall_before = 1, 0.0
    saved = checkpoint.load() if checkpoint is not None else None
    if saved is not None:
        tr.load_state_dict(saved["model"])
        opt_g.load_state_dict(saved["opt_g"])
        opt_d.load_state_dict(saved["opt_d"])
        for g, st in zip(gens, saved["generators"]):
            g.set_state(st)
        pools = [t.to(device) for t in saved["pools"]]
        best = [(loss_, state or None, it_) for loss_, state, it_ in
                zip(saved["best_loss"], saved["best_state"], saved["best_iteration"])]
        sums, curves = saved["sums"], saved["curves"]
        start, wall_before = saved["iteration"] + 1, saved["wall_s"]
        for k in range(n):  # the new MLflow runs get the curves up to the checkpoint too
            if logs[k]:
                for point in curves[k]:
                    logs[k]({key: v for key, v in point.items() if key != "iteration"}, point["iteration"])
        if progress is not None:
            progress.update(n * saved["iteration"])
        print(f"translator: resuming from {checkpoint.path} at iteration {saved['iteration']} of {cfg.iterations}",
              flush=True)
    t0 = time.perf_counter()
    for it in range(start, cfg.iterations + 1):
        if cfg.lr_decay != "none":
            for opt, scale in ((opt_g, 1.0), (opt_d, cfg.d_lr_scale)):
                for group in opt.param_groups:
                    group["lr"] = scale * cfg.learning_rate * lr_factor(cfg.lr_decay, it, cfg.iterations)
        batch = []
        for k in range(n):
            xd0, xd, xd2, pd_ = demo_s[k].sample(quarter)
            xr0, xr, xr2, pr = rand_s[k].sample(quarter)
            batch.append((torch.cat([xd0, xr0]), torch.cat([xd, xr]), torch.cat([xd2, xr2]), torch.cat([pd_, pr])))
        x0, x, x2, pidx = (torch.stack(parts) for parts in zip(*batch))
        n_demo = 2 * quarter  # the batch is [demonstrations, X random], each half both pairings
        out = losses(x0, x, x2, pidx)
        y_hat = out["y_hat"]
        # --- D step (fakes detached; with a pool, half of them come from past generators, as in Cycle-Dynamics)
        y_adv = y_hat if cfg.adv_on == "all" else y_hat[:, n_demo:]
        fake = y_adv.detach()
        fakes, reals = [], []
        for k in range(n):
            fake_k = fake[k]
            if cfg.history_size:
                if len(pools[k]):
                    n_old = len(fake_k) // 2
                    old = pools[k][torch.randint(0, len(pools[k]), (n_old,), generator=gens[k]).to(device)]
                    fake_d = torch.cat([fake_k[: len(fake_k) - n_old], old])
                else:
                    fake_d = fake_k
                pools[k] = torch.cat([pools[k], fake_k])[-cfg.history_size:]
            else:
                fake_d = fake_k
            fakes.append(fake_d)
            reals.append(y_real_all[torch.randint(0, len(y_real_all), (y_adv.shape[1],), generator=gens[k])
                                    .to(device)])
        y_real, fake_d = torch.stack(reals), torch.stack(fakes)
        d_both = tr.disc(torch.cat([y_real, fake_d], dim=1))
        d_real, d_fake = d_both[:, :y_real.shape[1]], d_both[:, y_real.shape[1]:]
        l_d = d_loss_fn(d_real, d_fake)
        opt_d.zero_grad(set_to_none=True)
        l_d.sum().backward()
        opt_d.step()
        # --- G step (D frozen: its weight gradients would be thrown away)
        tr.D.requires_grad_(False)
        l_adv = g_loss_fn(tr.disc(y_adv))
        loss = weighted_sum([(cfg.lambda_adv, l_adv), (cfg.lambda_dyn, out["dyn"]), (cfg.lambda_id, out["id"]),
                             (cfg.lambda_hand, out["hand"]), (cfg.lambda_side, out["side"])])
        opt_g.zero_grad(set_to_none=True)
        loss.sum().backward()
        opt_g.step()
        tr.D.requires_grad_(True)
        with torch.no_grad():
            acc = 0.5 * ((d_real > 0).float().mean(dim=(1, 2)) + (d_fake < 0).float().mean(dim=(1, 2)))
            values = torch.stack([l_d, l_adv, out["dyn"], out["id"], out["hand"], loss, acc, out["side"]]
                                 ).detach().cpu().numpy()
        for k in range(n):
            check_finite(float(values[5, k]), "the translator's G loss", it)
            check_finite(float(values[0, k]), "the translator's D loss", it)
            for j, key in enumerate(curve_keys):
                sums[k][key] = sums[k].get(key, 0.0) + float(values[j, k])
        if progress is not None:
            progress.update(n)
        log_now = it % cfg.log_every == 0 or it == cfg.iterations
        select_now = it % cfg.select_every == 0 or it == cfg.iterations
        if not (log_now or select_now):
            continue
        for k in range(n):
            point = None
            if log_now:
                cnt = cfg.log_every if it % cfg.log_every == 0 else it % cfg.log_every
                point = {key: v / cnt for key, v in sums[k].items()}
                sums[k] = {}
            if holds[k] is not None and select_now:
                one = tr.member(k)
                with torch.no_grad():
                    h = Losses(one, dyn, cfg, tl)(*holds[k])
                    sel = float(Losses(one, dyn, cfg, tl).selection(h)[0])
                point = point or {}
                point.update({"heldout/selection_loss": sel, "heldout/dyn": float(h["dyn"][0]),
                              "heldout/id": float(h["id"][0])})
                if sel < best[k][0]:
                    best[k] = (sel, one.state_dict(), it)
            if point is not None:
                curves[k].append({"iteration": it, **point})
                if logs[k]:
                    logs[k](point, it)
        if checkpoint is not None and select_now:  # the last too: a failure after training loses none of it
            checkpoint.save({
                "iteration": it, "model": tr.state_dict(), "opt_g": opt_g.state_dict(), "opt_d": opt_d.state_dict(),
                "generators": [g.get_state() for g in gens], "pools": [t.cpu() for t in pools],
                "best_loss": [b[0] for b in best], "best_state": [b[1] or {} for b in best],
                "best_iteration": [b[2] for b in best], "sums": sums, "curves": curves,
                "wall_s": wall_before + time.perf_counter() - t0})
    wall = wall_before + time.perf_counter() - t0
    out_trs, out_stats = [], []
    for k in range(n):
        one = tr.member(k)
        if best[k][1] is not None:  # the kept G (and hand offset); D stays the last iterate's
            state = one.state_dict()
            state.update({key: v for key, v in best[k][1].items() if not key.startswith("D.")})
            one.load_state_dict(state)
        one.cpu().eval()
        final = {key: v for key, v in (curves[k][-1] if curves[k] else {}).items() if key != "iteration"}
        out_trs.append(one)
        out_stats.append({"wall_time_s": wall, "iterations_per_s": cfg.iterations / wall, "curve": curves[k],
                          "final": final, "stack_size": n,
                          "selected_iteration": best[k][2] if best[k][1] is not None else cfg.iterations,
                          "selected_heldout_loss": best[k][0] if best[k][1] is not None else None})
    return out_trs, out_stats
