"""SAC expert training: resumable after a kill, saved as a state dict with its config, demos with schema."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import smoke
import yaml

from lfdt import data
from lfdt.config import DemosConfig, EnvConfig, ExpertsConfig
from lfdt.errors import StageError
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push import experts

ROOT = Path(__file__).resolve().parents[1]
TINY = ExpertsConfig(total_timesteps=1_200, n_envs=2, net_arch=[32, 32], batch_size=32, buffer_size=5_000,
                     learning_starts=200, checkpoint_every=400, log_every=200, eval_episodes=3)


@pytest.mark.parametrize("protocol", ["programmed_robot", "joint_expert"])
def test_train_save_load_and_demos(tmp_path, protocol):
    env_cfg = EnvConfig()
    demos_cfg = DemosConfig(protocol=protocol, per_pairing=2, success_only=False)
    logged = []
    model, stats = experts.train_expert("R1H", env_cfg, TINY, demos_cfg, tmp_path / "ckpt",
                                        log=lambda m, s: logged.append(s))
    assert stats["timesteps"] == TINY.total_timesteps and stats["resumed_from_timesteps"] == 0
    assert logged == list(range(200, 1_201, 200))
    assert (tmp_path / "ckpt" / "latest.json").exists()
    # the paper's protocol: the expert controls the human only; the other: both arms
    assert model.action_space.shape == ((4,) if protocol == "programmed_robot" else (7,))
    experts.save_expert(model, tmp_path / "expert", "R1H", env_cfg, TINY, demos_cfg, {"note": "tiny"})
    loaded, cfg = experts.load_expert(tmp_path / "expert")
    assert cfg["observation_columns"] == box_columns.state_columns("R1H") and cfg["note"] == "tiny"
    assert cfg["protocol"] == protocol
    obs = np.zeros(21)
    np.testing.assert_allclose(loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])
    ev = experts.evaluate_expert(loaded, "R1H", env_cfg, demos_cfg, 3, 0)
    assert ev["episodes"] == 3 and 0.0 <= ev["success_rate"] <= 1.0
    table, st = experts.collect_demos(loaded, "R1H", env_cfg, demos_cfg)
    path = data.write_table(table, tmp_path / "R1H.parquet")
    meta = data.check_transitions(path, "demos", "R1H", box_columns.BOX_PUSH)
    assert meta["robot"] == "r1" and meta["protocol"] == protocol
    assert st["demonstrations"] == 2 and st["attempts"] == 2
    df = data.read_transitions(path)
    assert [c for c in df.columns if c.startswith("action.")] == ["action.r1.tau0", "action.r1.tau1", "action.r1.tau2"]
    assert [c for c in df.columns if c.startswith("human_action.")] == [f"human_action.h.tau{i}" for i in range(4)]
    if protocol == "programmed_robot":
        # the recorded robot action is the program's command, never the policy's
        assert not np.allclose(df[[f"action.r1.tau{i}" for i in range(3)]].to_numpy(), 0.0)


def test_demos_fail_loudly_when_expert_cannot_succeed(tmp_path):
    model, _ = experts.train_expert("HR2", EnvConfig(), TINY.model_copy(update={"total_timesteps": 200}),
                                    DemosConfig(), tmp_path / "ckpt")
    with pytest.raises(StageError, match="demos.max_attempts = 3"):
        experts.collect_demos(model, "HR2", EnvConfig(), DemosConfig(per_pairing=3, max_attempts=3))


def test_checkpoint_of_other_params_is_not_resumed(tmp_path):
    env_cfg = EnvConfig()
    demos_cfg = DemosConfig()
    model, _ = experts.train_expert("R1H", env_cfg, TINY.model_copy(update={"total_timesteps": 400}), demos_cfg,
                                    tmp_path)
    other = experts.Checkpoints(tmp_path, experts.config_hash("R1H", env_cfg, TINY.model_copy(update={"gamma": 0.9}),
                                                              demos_cfg))
    assert other.latest() is None
    # another robot program is another run, too
    other_program = DemosConfig(program=demos_cfg.program.model_copy(
        update={"r1": demos_cfg.program.r1.model_copy(update={"speed": 0.05})}))
    tiny400 = TINY.model_copy(update={"total_timesteps": 400})
    assert experts.Checkpoints(tmp_path, experts.config_hash("R1H", env_cfg, tiny400, other_program)).latest() is None
    same = experts.Checkpoints(tmp_path, experts.config_hash("R1H", env_cfg, tiny400, demos_cfg))
    assert same.latest() is not None


@pytest.mark.slow
def test_killed_training_resumes_where_it_stopped(tmp_path):
    params = {"experts": {**TINY.model_dump(), "total_timesteps": 3_000, "checkpoint_every": 500},
              "demos": {"per_pairing": 1, "success_only": False}, "grid": {"demos": [1]},
              "translator": {"holdout_fraction": 0.0}}  # one demonstration leaves none to hold out (preflight's rule)
    full = yaml.safe_load((ROOT / "params.yaml").read_text())  # a stage takes only a complete params file
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(smoke.merge(full, params)))
    cmd = [sys.executable, str(ROOT / "stages/train_experts.py"), "--experts", "models/experts",  # both pairings
           "--checkpoints", "checkpoints/experts", "--reports", "reports/experts"]
    env = {**os.environ, "MLFLOW_TRACKING_URI": f"sqlite:///{tmp_path / 'mlflow.db'}"}
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    pointer = tmp_path / "checkpoints/experts/R1H/latest.json"
    deadline = time.time() + 240
    while time.time() < deadline:
        if pointer.exists() and json.loads(pointer.read_text())["num_timesteps"] >= 1_000:
            break
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    stopped_at = json.loads(pointer.read_text())["num_timesteps"]
    assert 1_000 <= stopped_at < 3_000
    assert not (tmp_path / "models/experts/R1H/policy.pt").exists()
    done = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / "reports/experts/R1H_train.json").read_text())
    assert report["resumed_from_timesteps"] == stopped_at
    assert "R1H: resuming from checkpoint checkpoints/experts/R1H/" in done.stderr  # the rerun says where it resumes
    assert f"at step {stopped_at:,} of 3,000" in done.stderr, done.stderr[-2000:]
    # the learning curve keeps its points from before the kill (every log_every = 200 steps, once each)
    with open(tmp_path / "reports/experts/R1H_curve.csv") as fh:
        steps = [int(r["timesteps"]) for r in csv.DictReader(fh)]
    assert steps == sorted(set(steps)) and min(steps) < stopped_at and max(steps) >= 2_800
    assert len(steps) == 3_000 // TINY.log_every
    for pairing in ("R1H", "HR2"):
        report = json.loads((tmp_path / f"reports/experts/{pairing}_train.json").read_text())
        assert report["timesteps"] == 3_000
        assert (tmp_path / f"models/experts/{pairing}/policy.pt").exists()
        assert not (tmp_path / f"checkpoints/experts/{pairing}").exists()  # cleaned up once the model is safe


def test_training_leaves_no_logger_folder_in_the_temp_dir(tmp_path, monkeypatch):
    """SB3 makes an SB3-<date> folder in the temp dir on every learn() unless the model has a logger of its own."""
    import tempfile

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    tiny = TINY.model_copy(update={"total_timesteps": 300, "checkpoint_every": 300, "log_every": 300})
    experts.train_expert("R1H", EnvConfig(), tiny, DemosConfig(), tmp_path / "ckpt")
    assert sorted(p.name for p in tmp.glob("SB3-*")) == []
