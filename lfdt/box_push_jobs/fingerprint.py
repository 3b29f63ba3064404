"""A small fixed workload through every numeric component of the pipeline, hashed: the same on every CPU, or not.

Each component runs the project's own code on tiny settings, from fixed seeds, and hashes the bytes of what it
produced (SHA-256, first 16 hex digits):

* ``mujoco_step``: the box push's environments of all three domains stepped by fixed commands (observations and
  rewards), and the batched ``mujoco.rollout`` of the random-motion collection;
* ``dynamics``: F and F^-1 fit for some iterations (weights, held-out errors);
* ``translator``: a stack of two translators trained with every loss and the checkpoint selection (weights);
* ``bc``: a stack of two BC policies with input noise (weights), then both acting in lockstep from evaluation
  start states (:func:`lfdt.evaluation.rollout_lockstep`: actions and outcomes);
* ``sac``: stable-baselines3's SAC gradient steps of the human stand-in beside its programmed robot (weights);
* ``statistics``: NumPy and SciPy statistics of the reports (normalisers, intervals over seeds and start states);
* ``pushes``: random-motion episodes that push the box (``random.push_fraction``), F's error on two-arm pushes in the
  box's frame (``reports/dynamics.json``'s ``pushes/``), and a translator trained with the sideways term
  (``translator.lambda_side``: weights and curves);
* ``diagnostics``: what the translator stage reports beside its weights, on that translator and the pushes taken
  as demonstrations: :func:`~lfdt.translation.apply.translator_diagnostics` (L_dyn split, D's accuracies, F^-1's
  labels, the kinematics' residuals), the translated demonstrations with their
  :func:`~lfdt.translation.apply.translation_diagnostics`, and their open-loop replay in MuJoCo
  (:func:`~lfdt.tasks.box_push.env.replay_check`): every value at full precision.

``python -m lfdt.box_push_jobs.fingerprint`` prints the hashes (``--out`` writes them as JSON); the ``fingerprint``
stage writes ``reports/fingerprint.json``, and ``tests/test_fingerprint.py`` recomputes them and compares. Where the
numeric code paths are pinned (:mod:`lfdt.numerics`), every x86-64 CPU with AVX2 should give the committed hashes; a
component that differs names the library whose kernels moved. ``tools/cross_cpu.py`` runs this module on other CPU
models under QEMU.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from lfdt import data, layout, numerics

PINNED_LOSS = {"lambda_dyn": 10.0, "lambda_id": 100.0, "learning_rate": 3e-4}
"""The fingerprint's translator weights and learning rate, written out: its hashes (and the cross-CPU runs that
compare them) do not move when the pipeline's translator defaults do."""

COMPONENTS = ("mujoco_step", "dynamics", "translator", "bc", "sac", "statistics", "pushes", "diagnostics")
"""The components hashed, in the order they run."""


def _hash(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        if isinstance(a, torch.Tensor):
            a = a.detach().cpu().numpy()
        if isinstance(a, dict):
            for k in sorted(a):
                h.update(k.encode())
                h.update(_hash(a[k]).encode())
            continue
        h.update(np.ascontiguousarray(np.asarray(a)).tobytes())
    return h.hexdigest()[:16]


def _mujoco() -> tuple[str, dict]:
    from lfdt.config import EnvConfig, RandomConfig
    from lfdt.tasks.box_push.env import BoxPushEnv
    from lfdt.tasks.box_push.random_motion import collect_random

    env_cfg = EnvConfig()
    parts = []
    for domain in layout.DOMAINS:
        env = BoxPushEnv(domain, env_cfg)
        obs, _ = env.reset(seed=12345)
        t = np.arange(env.action_space.shape[0])
        traj = [obs]
        for i in range(40):
            obs, reward, *_ = env.step(0.8 * np.sin(0.3 * i + t))
            traj.append(np.r_[obs, reward])
        parts.append(np.concatenate(traj))
    table, _ = collect_random("Y", env_cfg, RandomConfig(transitions=600, episodes_per_batch=3, threads=1,
                                                         push_fraction=0.0))
    parts.append(table.to_pandas().drop(columns=[], errors="ignore").select_dtypes("number").to_numpy())
    return _hash(*parts), {"random_motion": table}


def _dynamics(random_y_table) -> tuple[str, object]:
    from lfdt.config import DynamicsConfig
    from lfdt.dynamics import RandomY, fit_dynamics
    from lfdt.tasks.box_push import columns as box_columns

    df = random_y_table.to_pandas()
    cols, acts = box_columns.state_columns("Y"), box_columns.action_columns("Y")
    d = RandomY(df[[layout.STATE_PREFIX + c for c in cols]].to_numpy(np.float32, copy=True),
                df[[layout.ACTION_PREFIX + c for c in acts]].to_numpy(np.float32, copy=True),
                df[[layout.NEXT_STATE_PREFIX + c for c in cols]].to_numpy(np.float32, copy=True),
                df.episode_index.to_numpy(), cols, acts)
    models, res = fit_dynamics(d, DynamicsConfig(hidden=[32, 32], iterations=60, eval_every=30, batch_size=32))
    return _hash(models.state_dict(), np.array([res["forward_mse"], res["inverse_mse"]])), models


def _translator(random_y_table, dyn) -> str:
    from lfdt.box_push_jobs.translator import box_push_kinematics
    from lfdt.config import EnvConfig, TranslatorConfig
    from lfdt.tasks.box_push import columns as box_columns
    from lfdt.translation.training import Member, train_translators
    from lfdt.translation.transitions import Transitions, split_held_out

    df = random_y_table.to_pandas()
    tl = box_columns.BOX_PUSH
    # X data: Y's random motion relabelled as each pairing's (the shapes of X; what matters is the arithmetic)
    rng = np.random.default_rng(5)
    sets = {}
    for p in layout.PAIRINGS:
        cols = tl.canonical_x_columns(p)
        n = len(df)
        x = rng.normal(size=(n, len(cols))).astype(np.float32)
        ep = df.episode_index.to_numpy()
        first = np.r_[True, ep[1:] != ep[:-1]]
        sets[p] = Transitions(x, x + 0.05 * rng.normal(size=x.shape).astype(np.float32), ep,
                              df.frame_index.to_numpy(), None, np.where(first[:, None], x, np.roll(x, 1, axis=0)))
    y = df[[layout.STATE_PREFIX + c for c in tl.state_columns("Y")]].to_numpy(np.float32, copy=True)
    members = []
    for seed in (1, 2):
        train, held = split_held_out(sets, 0.34, seed)
        members.append(Member(train, seed, held))
    cfg = TranslatorConfig(hidden=[32, 32], iterations=30, batch_size=16, select_every=10, log_every=10,
                           hand_offset=True, lambda_hand=1.0, lambda_side=0.0, **PINNED_LOSS)
    trs, stats = train_translators(members, sets, y, dyn, cfg, tl=tl, kinematics=box_push_kinematics(EnvConfig()))
    lsgan, _ = train_translators(members[:1], sets, y, dyn,
                                 cfg.model_copy(update={"gan_loss": "lsgan", "iterations": 10}), tl=tl,
                                 kinematics=box_push_kinematics(EnvConfig()))
    curves = np.array([[v for c in st["curve"] for v in c.values()] for st in stats])
    return _hash(*(t.state_dict() for t in trs), lsgan[0].state_dict(), curves)


def _bc() -> str:
    from lfdt import bc, evaluation
    from lfdt.box_push_jobs.evaluate import box_push_trials
    from lfdt.config import BCConfig, EnvConfig
    from lfdt.tasks.box_push import columns as box_columns

    tl = box_columns.BOX_PUSH
    cols, acts = tl.state_columns("Y"), tl.action_columns("Y")
    tasks, rng = [], np.random.default_rng(3)
    for _ in range(2):
        s = rng.normal(size=(300, len(cols))).astype(np.float32)
        df = pd.DataFrame(s, columns=[layout.STATE_PREFIX + c for c in cols])
        df[[layout.ACTION_PREFIX + c for c in acts]] = np.tanh(s[:, :len(acts)])
        df["episode_index"] = np.arange(300) // 30
        tasks.append(bc.tasks_for("lfdt", translated=df, tl=tl)[0])
    members, _ = bc.train_members(tasks, BCConfig(hidden=[32, 32], iterations=40, eval_every=20, batch_size=16,
                                                  input_noise=0.1), [1, 2])
    policies = [bc.BCPolicy([m], tl) for m in members]
    trials = box_push_trials(bc.StackedPolicies(policies), 2, EnvConfig(), trials=3, purpose="development")
    outcome = np.array([[t["success"], t["steps"], t["final_box_distance_m"], t["final_yaw_error_rad"]]
                        for per in trials for t in per])
    evaluation.PAPER_TRIALS  # noqa: B018  (the module's constants are part of the evaluation above)
    return _hash(*(m.state_dict() for m in members), outcome)


def _sac() -> str:
    from lfdt import stage  # noqa: F401  (the project's params defaults)
    from lfdt.config import DemosConfig, EnvConfig, ExpertsConfig
    from lfdt.seeding import seed_everything
    from lfdt.tasks.box_push import experts

    cfg = ExpertsConfig(learning_starts=40, batch_size=32, buffer_size=1000, n_envs=2, net_arch=[32, 32])
    seed_everything(0)
    venv = experts.make_vec_env("R1H", EnvConfig(), DemosConfig(), cfg.n_envs, 0)
    model = experts.build_sac(venv, cfg)
    model.learn(120, progress_bar=False)
    venv.close()
    return _hash(model.policy.state_dict(), model.log_ent_coef)


def _statistics() -> str:
    from lfdt.evaluation import seed_state_interval, wilson_interval
    from lfdt.nets import Normalizer

    rng = np.random.default_rng(11)
    x = rng.normal(size=(500, 19)) * rng.uniform(0.01, 3, size=19) + rng.normal(size=19)
    norm = Normalizer.fit(x.astype(np.float32), 1e-2)
    outcomes = (rng.uniform(size=(10, 200)) < rng.uniform(0.5, 0.95, size=(10, 1))).astype(float)
    values = [*seed_state_interval(outcomes), *seed_state_interval(outcomes[:1]), *wilson_interval(171, 200),
              float(np.exp(x).std()), float(np.log1p(np.abs(x)).mean()), float(np.arctan2(x[:, 0], x[:, 1]).sum())]
    return _hash(norm.mean, norm.std, np.array(values))


def _pushes(random_y_table, dyn) -> str:
    from lfdt.box_push_jobs.translator import box_push_kinematics
    from lfdt.config import EnvConfig, RandomConfig, TranslatorConfig
    from lfdt.dynamics import object_frame_ratios
    from lfdt.tasks.box_push import columns as box_columns
    from lfdt.tasks.box_push.random_motion import collect_random, push_probe
    from lfdt.translation.training import Member, train_translators
    from lfdt.translation.transitions import load_x_transitions

    env_cfg = EnvConfig()
    tl = box_columns.BOX_PUSH
    tables = {d: collect_random(d, env_cfg, RandomConfig(transitions=400, episode_steps=40, episodes_per_batch=5,
                                                         threads=1, push_fraction=0.5))[0] for d in layout.DOMAINS}
    probe = object_frame_ratios(dyn, *push_probe(env_cfg, episodes=4, steps=30), tl)
    with tempfile.TemporaryDirectory() as tmp:
        sets = {p: load_x_transitions(data.write_table(tables[p], Path(tmp) / f"{p}.parquet"), p, tl=tl,
                                      kind="random") for p in layout.PAIRINGS}
    y = tables["Y"].to_pandas()[[layout.STATE_PREFIX + c for c in tl.state_columns("Y")]].to_numpy(np.float32,
                                                                                                 copy=True)
    cfg = TranslatorConfig(hidden=[32, 32], iterations=20, batch_size=16, select_every=10, log_every=10,
                           lambda_side=1.0, **PINNED_LOSS)
    trs, stats = train_translators([Member(sets, 3, None)], sets, y, dyn, cfg, tl=tl,
                                   kinematics=box_push_kinematics(env_cfg))
    curves = np.array([[v for c in st["curve"] for v in c.values()] for st in stats])
    numbers = [tables[d].to_pandas().select_dtypes("number").to_numpy() for d in layout.DOMAINS]
    return (_hash(*numbers, np.array([probe["across"], probe["along"], probe["angle"]]), trs[0].state_dict(), curves),
            {"tables": tables, "translator": trs[0], "cfg": cfg, "y": y})


def _diagnostics(pushes: dict, dyn) -> str:
    from lfdt.box_push_jobs.translator import box_push_kinematics, measure_translation
    from lfdt.config import EnvConfig
    from lfdt.tasks.box_push import columns as box_columns
    from lfdt.translation.transitions import load_x_transitions

    env_cfg = EnvConfig()
    tl = box_columns.BOX_PUSH
    with tempfile.TemporaryDirectory() as tmp:
        paths, demos = {}, {}
        for p in layout.PAIRINGS:
            table = pushes["tables"][p]
            meta = {**data.read_schema_metadata(table.schema), "kind": "demos"}  # the pushes stand in for demos
            paths[p] = data.write_table(table.replace_schema_metadata({data.META_KEY: json.dumps(meta).encode()}),
                                        Path(tmp) / f"{p}.parquet")
            demos[p] = load_x_transitions(paths[p], p, tl=tl, with_actions=True, kind="demos")
        episodes = {p: sorted(int(e) for e in np.unique(demos[p].episode)) for p in layout.PAIRINGS}
        # the translator stage's own measurement, with the pushes as its random motion too
        df, diag = measure_translation([pushes["translator"]], dyn, pushes["cfg"], paths, episodes, demos, demos,
                                       pushes["y"], box_push_kinematics(env_cfg), env_cfg, seed=4, max_random=200)
    return _hash(df.select_dtypes("number").to_numpy(), np.array([diag[k] for k in sorted(diag)], dtype=np.float64))


def compute(only: list[str] | None = None, log: Callable[[str], None] | None = None) -> dict[str, str]:
    """The hash of each component (all of :data:`COMPONENTS`, or ``only`` those)."""
    torch.set_num_threads(1)
    want = set(only or COMPONENTS)
    out: dict[str, str] = {}

    def note(name: str, t0: float) -> None:
        if log:
            log(f"{name}: {out[name]} ({time.perf_counter() - t0:.1f} s)")

    t0 = time.perf_counter()
    mj, data = _mujoco()
    if "mujoco_step" in want:
        out["mujoco_step"] = mj
        note("mujoco_step", t0)
    dyn = None
    if want & {"dynamics", "translator", "pushes", "diagnostics"}:
        t0 = time.perf_counter()
        h, dyn = _dynamics(data["random_motion"])
        if "dynamics" in want:
            out["dynamics"] = h
            note("dynamics", t0)
    for name, fn in (("translator", lambda: _translator(data["random_motion"], dyn)), ("bc", _bc), ("sac", _sac),
                     ("statistics", _statistics)):
        if name in want:
            t0 = time.perf_counter()
            out[name] = fn()
            note(name, t0)
    if want & {"pushes", "diagnostics"}:  # the diagnostics measure the pushes' translator
        t0 = time.perf_counter()
        h, pushes = _pushes(data["random_motion"], dyn)
        if "pushes" in want:
            out["pushes"] = h
            note("pushes", t0)
        if "diagnostics" in want:
            t0 = time.perf_counter()
            out["diagnostics"] = _diagnostics(pushes, dyn)
            note("diagnostics", t0)
    return out


def report(hashes: dict[str, str]) -> dict:
    """The fingerprint as written to ``reports/fingerprint.json``: the hashes and what they depend on apart from the
    CPU (numerics mode, library versions), never the machine itself."""
    import mujoco
    import scipy
    import stable_baselines3

    return {"numerics": numerics.mode(), "components": hashes,
            "versions": {"numpy": np.__version__, "torch": torch.__version__, "mujoco": mujoco.__version__,
                         "scipy": scipy.__version__, "stable_baselines3": stable_baselines3.__version__,
                         "python": sys.version.split()[0]}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, help="write the fingerprint (JSON) here")
    ap.add_argument("--only", nargs="*", choices=COMPONENTS, help="some components only")
    args = ap.parse_args()
    info = numerics.describe()
    print(f"numerics {info['numerics']} on {info['cpu_model']} ({info['cpu_isa']})", file=sys.stderr)
    doc = report(compute(args.only, log=lambda m: print(m, file=sys.stderr)))
    text = json.dumps(doc, indent=2, sort_keys=True) + "\n"
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    print(text, end="")


if __name__ == "__main__":
    main()
