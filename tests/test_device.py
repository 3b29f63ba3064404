"""The ``device`` setting: the CPU by default, checked where it enters, training on another device where one exists
(those tests need CUDA and are skipped on a machine without it, such as this project's CI)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from lfdt import bc, layout
from lfdt.config import (
    BCConfig,
    DynamicsConfig,
    EnvConfig,
    ExpertsConfig,
    ParamsError,
    RandomConfig,
    TranslatorConfig,
    validate_params,
)
from lfdt.dynamics import RandomY, fit_dynamics
from lfdt.errors import DeviceError
from lfdt.nets import torch_device
from lfdt.tasks.box_push import columns as box_columns
from lfdt.translation.training import train_translator
from lfdt.translation.transitions import load_x_transitions, split_held_out

ROOT = Path(__file__).resolve().parents[1]
cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


def test_cpu_is_the_default():
    assert validate_params({}).device == "cpu"
    assert torch_device("cpu") == torch.device("cpu")


@pytest.mark.parametrize("bad", ["gpu", "cuda:", "cuda:-1", "CPU", "tpu", "cuda:0 "])
def test_schema_refuses_an_unknown_device(bad):
    with pytest.raises(ParamsError, match=r"device = "):
        validate_params({"device": bad})


def test_a_missing_cuda_device_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(DeviceError, match=r"device = 'cuda', but torch .* finds no CUDA device .*set device: cpu"):
        torch_device("cuda")


def test_a_cuda_index_beyond_the_machine_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    with pytest.raises(DeviceError, match=r"device = 'cuda:1', but this machine has 1 CUDA device"):
        torch_device("cuda:1")
    assert torch_device("cuda:0") == torch.device("cuda:0")


@pytest.mark.parametrize("args", [
    ["stages/train_experts.py", "--experts", "models/experts", "--checkpoints", "checkpoints/experts",
     "--reports", "reports/experts"],
    ["stages/fit_dynamics.py", "--random-dir", "data/random", "--out-dir", "models/dynamics", "--report",
     "reports/dynamics.json", "--curve", "reports/dynamics_curve.csv"],
    ["stages/train_translator.py", "--method", "lfdt", "--demos", "50", "--demos-dir", "data/demos", "--random-dir",
     "data/random", "--dynamics-dir", "models/dynamics", "--translators", "models/translator", "--bc-data",
     "data/bc_train", "--reports", "reports/translator", "--checkpoints", "checkpoints/translator"],
    ["stages/train_bc.py", "--method", "lfdt", "--demos", "50", "--bc-data", "data/bc_train", "--dynamics-dir",
     "models/dynamics", "--policies", "models/bc", "--reports", "reports/bc"],
    ["stages/twin_train.py", "--task", "block_push", "--data-dir", "data/twin", "--models", "models/twin",
     "--reports", "reports/twin"],
])
def test_every_training_stage_stops_on_a_missing_device_before_any_work(tmp_path, args):
    params = tmp_path / "params.yaml"
    params.write_text((ROOT / "params.yaml").read_text().replace("device: cpu", "device: cuda", 1))
    env = {**os.environ, "CUDA_VISIBLE_DEVICES": "", "MLFLOW_TRACKING_URI": f"sqlite:///{tmp_path}/mlflow.db"}
    proc = subprocess.run([sys.executable, str(ROOT / args[0]), *args[1:], "--params", str(params)], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "device = 'cuda'" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "mlflow.db").exists() and not any(p.name != "params.yaml" for p in tmp_path.iterdir())


def _random_y(n: int = 2_000, seed: int = 0) -> RandomY:
    rng = np.random.default_rng(seed)
    y = rng.normal(size=(n, 19)).astype(np.float32)
    a = rng.uniform(-1, 1, size=(n, 6)).astype(np.float32)
    y2 = (y + 0.05 * np.tanh(a @ rng.normal(size=(6, 19)))).astype(np.float32)
    return RandomY(y=y, a=a, y2=y2, episode=np.repeat(np.arange(n // 20), 20),
                   state_columns=box_columns.state_columns("Y"), action_columns=box_columns.action_columns("Y"))


def _on_cpu(module: torch.nn.Module) -> bool:
    return all(t.device.type == "cpu" for t in [*module.parameters(), *module.buffers()])


@cuda
def test_dynamics_and_bc_train_on_cuda_and_come_back_on_the_cpu():
    d = _random_y()
    cfg = DynamicsConfig(iterations=300, eval_every=100, batch_size=64, hidden=[32, 32])
    models_gpu, res_gpu = fit_dynamics(d, cfg, device="cuda")
    models_cpu, res_cpu = fit_dynamics(d, cfg)
    assert _on_cpu(models_gpu)
    # the same minibatches on both devices: the same model up to float rounding
    assert res_gpu["forward_mse"] == pytest.approx(res_cpu["forward_mse"], rel=0.05)
    frame = pd.DataFrame({**{f"state.{c}": d.y[:, i] for i, c in enumerate(d.state_columns)},
                          **{f"action.{c}": d.a[:, i] for i, c in enumerate(d.action_columns)},
                          "episode_index": d.episode})
    task = bc.BCTask("pi", d.state_columns, d.action_columns, frame)
    bcfg = BCConfig(hidden=[32], iterations=200, eval_every=50, batch_size=64, input_noise=0.1)
    member, st = bc.train_member(task, bcfg, seed=0, device="cuda")
    _, st_cpu = bc.train_member(task, bcfg, seed=0)
    assert _on_cpu(member) and st["best_val_loss"] == pytest.approx(st_cpu["best_val_loss"], rel=0.05)


@cuda
def test_translator_trains_on_cuda_and_comes_back_on_the_cpu(tmp_path):
    from lfdt import data
    from lfdt.dynamics import DynamicsModels
    from lfdt.tasks.box_push.random_motion import collect_random

    paths = {}
    for dom in layout.DOMAINS:
        table, _ = collect_random(dom, EnvConfig(), RandomConfig(transitions=1_000, episodes_per_batch=20))
        paths[dom] = data.write_table(table, tmp_path / f"{dom}.parquet")
    dyn = DynamicsModels(19, 6, [32, 32])
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=box_columns.BOX_PUSH)
                for p in layout.PAIRINGS}
    train, held = split_held_out(random_x, 0.25, seed=0)
    cfg = TranslatorConfig(iterations=100, hidden=[32, 32], log_every=50, select_every=50, batch_size=32,
                           kinematics="learned", history_size=64)
    y = np.random.default_rng(0).normal(size=(500, 19)).astype(np.float32)
    tr, stats = train_translator(train, random_x, y, dyn, cfg, seed=0, held_out=held, device="cuda",
                                 tl=box_columns.BOX_PUSH)
    assert _on_cpu(tr) and _on_cpu(dyn) and np.isfinite(stats["selected_heldout_loss"])


@cuda
def test_sac_expert_trains_on_cuda_and_saves_a_cpu_policy(tmp_path):
    from lfdt.config import DemosConfig
    from lfdt.tasks.box_push import experts

    cfg = ExpertsConfig(total_timesteps=400, n_envs=2, learning_starts=100, batch_size=32, net_arch=[32],
                        checkpoint_every=200, log_every=200, eval_episodes=1)
    model, _ = experts.train_expert("R1H", EnvConfig(), cfg, DemosConfig(), tmp_path / "ckpt", device="cuda")
    experts.save_expert(model, tmp_path / "out", "R1H", EnvConfig(), cfg, DemosConfig(), {})
    state = torch.load(tmp_path / "out" / "policy.pt", weights_only=True)
    assert all(v.device.type == "cpu" for v in state.values())
    loaded, _ = experts.load_expert(tmp_path / "out")
    assert loaded.device.type == "cpu"
