"""lfdt.rig.base and the rig commands of ``python -m lfdt.robot``: recordings that survive a kill or Ctrl-C,
demonstrations and deployment on the twin (--sim), and RealRig against fake hardware (pymycobot talking to
FakeMyCobot on pseudo-terminals, and a synthetic AprilTag video as the camera).
"""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest

from lfdt import data, twin
from lfdt.poses import invert_pose
from lfdt.rig.recording import EpisodeRecorder, RecordingMismatch, read_recording, record_random_episode
from lfdt.rig.sim import SimRig
from lfdt.robot import fake_mycobot as fm
from lfdt.robot import kinematics
from lfdt.robot.arm import SafetyError, SimArm, TrackingLost
from lfdt.robot.calibration import calibration_from_intrinsics, save_calibration
from lfdt.robot.cli import TASKS, build_parser, main
from lfdt.robot.real_rig import CLIP_MARGIN_MM, RealRig
from lfdt.robot.rig_config import (
    RigConfigError,
    example_rig_config,
    load_rig_config,
    parse_rig_config,
    write_rig_config,
)
from lfdt.robot.tracker import ObjectPose, TrackedFrame, make_pose
from lfdt.tasks import registry
from lfdt.twin import collect as twin_collect
from lfdt.twin import common as twin_common
from lfdt.twin import evaluate as twin_evaluate
from lfdt.twin import train as twin_train

ROOT = Path(__file__).resolve().parents[1]
STEPS = 30
STEP_DELAY = 0.02  # s per step: an episode takes ~0.6 s, so a kill lands mid-episode, not mid-write


# ------------------------------------------------------------------------------------------------ configuration


def test_example_config_is_valid_and_errors_name_the_key(tmp_path: Path) -> None:
    for task in TASKS:
        cfg = parse_rig_config(json.dumps(example_rig_config(task)))
        assert cfg.task == task and set(cfg.arms) == {"r1", "r2"}
    bad = example_rig_config()
    bad["arms"]["r1"]["host"] = "10.0.0.2"  # both port and host
    bad["arms"]["r2"]["speed"] = 0
    bad["camera"]["hand_tag_id"] = 0
    with pytest.raises(RigConfigError) as e:
        parse_rig_config(json.dumps(bad), "rig.json")
    msg = str(e.value)
    assert msg.startswith("rig.json: ")
    assert "arms.r1: give exactly one of 'port' (serial) or 'host' (TCP)" in msg
    assert "arms.r2.speed: Input should be greater than or equal to 1" in msg
    assert "camera: table_tag_id, hand_tag_id and object_tag_id must differ" in msg
    bad = example_rig_config()
    bad["arms"]["r1"]["workspace_max_mm"] = [240.0, 90.0, 95.0]  # the flange plane z = 100 is outside
    with pytest.raises(RigConfigError, match=r"arms\.r1: the task plane \(z = 100 mm\) is outside"):
        parse_rig_config(json.dumps(bad))
    bad = example_rig_config()
    bad["arms"]["r2"]["base"]["pitch_deg"] = 80.0
    with pytest.raises(RigConfigError, match=r"arms\.r2\.base: the arm's block_push plane is more than 60 deg"):
        parse_rig_config(json.dumps(bad))
    with pytest.raises(RigConfigError, match="cannot read rig config"):
        load_rig_config(tmp_path / "missing.json")
    # written example: relative camera paths resolve from the file's folder; no overwrite without --force
    assert main(["write-rig-config", "--out", str(tmp_path / "rig.json")]) == 0
    cfg = load_rig_config(tmp_path / "rig.json")
    assert cfg.camera.calibration == str(tmp_path / "calib.json") and cfg.camera.source == 0
    assert main(["write-rig-config", "--out", str(tmp_path / "rig.json")]) == 2
    write_rig_config(tmp_path / "rig.json", "peg_insertion", overwrite=True)
    assert load_rig_config(tmp_path / "rig.json").task == "peg_insertion"


def test_cli_lists_match_the_pipeline() -> None:
    assert TASKS == registry.PLANAR
    a = build_parser().parse_args(["record-random", "--sim", "--task", "block_push", "--domain", "Y", "--episodes",
                                   "1", "--steps", "2", "--out", "x"])
    assert a.func.__name__ == "run_record_random" and a.seed == 0 and a.step_delay == 0.0
    with pytest.raises(SystemExit):
        build_parser().parse_args(["deploy", "--sim", "--method", "lfdt", "--models", "m", "--trials", "1",
                                   "--log", "l.csv"])  # --task is required


def test_real_commands_need_a_rig(capsys) -> None:
    assert main(["record-random", "--domain", "Y", "--episodes", "1", "--steps", "2", "--out", "x"]) == 2
    assert "--rig RIG_JSON is required" in capsys.readouterr().err


# ------------------------------------------------------------------------------------ recordings survive a kill


def _start_recording(tmp_path: Path) -> tuple[subprocess.Popen, Path, Path]:
    out = tmp_path / "random_Y"
    log = tmp_path / "stderr.txt"
    with open(log, "w") as fh:
        proc = subprocess.Popen(
            [sys.executable, "-m", "lfdt.robot", "record-random", "--sim", "--task", "block_push", "--domain", "Y",
             "--episodes", "50", "--steps", str(STEPS), "--out", str(out), "--step-delay", str(STEP_DELAY)],
            cwd=ROOT, stdout=fh, stderr=subprocess.STDOUT)
    return proc, out, log


def _episode_files(out: Path) -> list[Path]:
    return sorted(out.glob("episode_*.parquet"))


def _wait_mid_episode(proc: subprocess.Popen, out: Path, timeout: float = 60.0) -> int:
    """Wait until 2 episodes exist and a further one has just been written, then half an episode more."""
    deadline = time.monotonic() + timeout
    while len(_episode_files(out)) < 2:
        assert proc.poll() is None, "recorder exited early"
        assert time.monotonic() < deadline, "no episodes written"
        time.sleep(0.02)
    n = len(_episode_files(out))
    while len(_episode_files(out)) == n:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    time.sleep(STEPS * STEP_DELAY / 2)
    return len(_episode_files(out))


def _assert_only_finished_episodes(out: Path) -> int:
    files = _episode_files(out)
    assert [f.name for f in files] == [f"episode_{i:06d}.parquet" for i in range(len(files))]
    for i, f in enumerate(files):
        t = pq.read_table(f).to_pandas()
        assert len(t) == STEPS, f"{f.name} has {len(t)} frames"
        assert (t.episode_index == i).all() and t.frame_index.tolist() == list(range(STEPS))
        assert not t.isna().any().any()
    data.check_transitions(out, "random", "Y", registry.get("block_push").layout)
    assert len(read_recording(out)) == STEPS * len(files)
    # anything else is the metadata or a temporary that never got a final name
    others = [p.name for p in out.iterdir() if p not in files]
    assert all(n == "_meta.json" or (n.startswith(".") and ".tmp-" in n) for n in others), others
    return len(files)


def test_recording_survives_sigkill(tmp_path: Path) -> None:
    proc, out, _ = _start_recording(tmp_path)
    try:
        at_kill = _wait_mid_episode(proc, out)
        proc.send_signal(signal.SIGKILL)
        assert proc.wait(timeout=10) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    kept = _assert_only_finished_episodes(out)
    assert kept == at_kill >= 3  # the episode in progress left nothing behind
    leftovers = [p.name for p in out.iterdir() if p.name.startswith(".")]
    print(f"SIGKILL mid-episode: {kept} complete episodes of {STEPS} frames, temporaries left: {leftovers}")


def test_recording_stops_cleanly_on_ctrl_c(tmp_path: Path) -> None:
    proc, out, log = _start_recording(tmp_path)
    try:
        at_signal = _wait_mid_episode(proc, out)
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    text = log.read_text()
    assert code == 130, text
    kept = _assert_only_finished_episodes(out)
    assert kept == at_signal
    assert f"interrupted: arms stopped; {kept} finished episodes in {out}, the episode in progress was dropped" \
        in text
    assert "Traceback" not in text


# -------------------------------------------------------------------------------------- demos and deploy (twin)


def test_record_demos_sim_keeps_successful_episodes(tmp_path: Path, capsys) -> None:
    out = tmp_path / "demos_HR2"
    assert main(["record-demos", "--sim", "--task", "peg_insertion", "--pairing", "HR2", "--episodes", "2",
                 "--out", str(out)]) == 0
    assert "kept 2 successful demonstrations" in capsys.readouterr().out
    meta = data.check_transitions(out, "demos", "HR2", registry.get("peg_insertion").layout)
    assert meta["source"] == "twin" and meta["task"] == "peg_insertion"
    df = data.read_transitions(out)
    assert sorted(df.episode_index.unique()) == [0, 1]
    assert [c for c in df.columns if c.startswith("action.")] == ["action.r2.dx", "action.r2.dz"]
    # the same episodes as the twin's own scripted demonstrations (same seeds, same program, same person)
    twin_collect.record_demos("peg_insertion", "HR2", 2, 0, tmp_path / "twin_demos")
    np.testing.assert_array_equal(df.to_numpy(), data.read_transitions(tmp_path / "twin_demos").to_numpy())


@pytest.fixture(scope="module")
def tiny_models(tmp_path_factory) -> Path:
    from lfdt.config import BCConfig, DynamicsConfig, TranslatorConfig, TwinParams
    root = tmp_path_factory.mktemp("twin")
    p = TwinParams(random_samples=120, random_episode_steps=20, demos_per_pairing=2, trials=2, videos=0,
                   dynamics=DynamicsConfig(hidden=[32, 32], iterations=30, eval_every=10),
                   translator=TranslatorConfig(hidden=[32, 32], iterations=20, log_every=10, kinematics="learned"),
                   bc=BCConfig(hidden=[32, 32], iterations=20, eval_every=10))
    twin_collect.collect("block_push", p.model_copy(update={"seeds": [0]}), root=root / "data")
    twin_train.train("block_push", p, 0, root / "models" / "s0", root=root / "data")
    return root / "models" / "s0"


def test_deploy_sim_appends_trials_the_stage_can_read(tiny_models: Path, tmp_path: Path, capsys) -> None:
    real_dir = tmp_path / "real"
    for method in twin.TWIN_METHODS:
        log = real_dir / "block_push" / f"deploy_{method}.csv"
        args = ["deploy", "--sim", "--task", "block_push", "--method", method, "--models", str(tiny_models),
                "--log", str(log)]
        assert main([*args, "--trials", "2"]) == 0
        assert main([*args, "--trials", "1"]) == 0  # appends: trial numbers continue
        with open(log, newline="") as fh:
            rows = list(csv.reader(fh))
        assert rows[0] == ["trial", "success"] and [r[0] for r in rows[1:]] == ["0", "1", "2"]
        assert all(r[1] in ("True", "False") for r in rows[1:])
        # the twin evaluation of the same policy from the same start states gives the same outcomes
        policy = twin_evaluate.load_policy("block_push", method, tiny_models)
        expected = [str(r["success"]) for r in twin_evaluate.evaluate_policy("block_push", policy, 3)]
        assert [r[1] for r in rows[1:]] == expected
    assert "block_push lfdt: " in capsys.readouterr().out
    spec = importlib.util.spec_from_file_location("twin_evaluate_stage", ROOT / "stages" / "twin_evaluate.py")
    stage = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(stage)
    rows = stage.real_trials("block_push", str(real_dir))
    assert [(r["method"], r["trial"]) for r in rows] == [(m, i) for m in twin.TWIN_METHODS for i in range(3)]


def test_sim_rig_interface() -> None:
    rig = SimRig("block_push", "R1H", seed=1, human="random")
    try:
        obs = rig.reset(seed=5)
        assert obs.shape == (7,) and rig.robots == ("r1",) and rig.human_slot == 1
        assert rig.state_columns() == registry.get("block_push").layout.state_columns("R1H")
        with pytest.raises(ValueError, match=r"domain R1H commands \['r1'\]"):
            rig.act({"r1": [0.0, 0.0], "r2": [0.0, 0.0]})
        with pytest.raises(ValueError, match="human_target"):
            rig.act({"r1": [0.004, 0.004]})  # the random person goes where the recording loop says
        rig.act({"r1": [0.004, 0.004]}, human_target=[0.003, -0.002])
        nxt = rig.observe()
        assert not np.allclose(nxt[:2], obs[:2]) and not rig.done
        np.testing.assert_array_equal(rig.human_action(obs, nxt), [0.003, -0.002])
    finally:
        rig.close()


# ------------------------------------------------------------------------------------ RealRig on fake hardware

sys.path.insert(0, str(Path(__file__).parent))
from test_tracker import H, K, W, render_tags, rot  # noqa: E402  (the tracker tests' tag renderer)

TABLE_ID, HAND_ID, OBJ_ID = 0, 1, 2
TABLE_SIZE, TAG = 0.08, 0.065
TABLE_AT_MM = (100.0, 280.0, 0.0)
HAND_AT = (0.10, 0.06, 0.03)
OBJ_AT, OBJ_YAW = (-0.06, 0.16, 0.015), 10.0
GOOD_FRAMES, LOST_FRAMES = 5, 3


def _world_from_camera() -> np.ndarray:
    # 0.6 m above the table looking straight down; image right = world +x, image down = world -y
    return make_pose(np.column_stack([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]]), (0.0, 0.12, 0.6))


@pytest.fixture(scope="module")
def camera_files(tmp_path_factory) -> tuple[Path, Path]:
    """A video of the table tag, the hand tag and the object tag (frames 0-4), then 3 frames with only the table tag;
    and the camera's calibration JSON."""
    d = tmp_path_factory.mktemp("camera")
    c_from_w = invert_pose(_world_from_camera())
    table = make_pose(np.eye(3), np.array(TABLE_AT_MM) / 1e3)
    hand = make_pose(rot("z", -20.0), HAND_AT)
    obj = make_pose(rot("z", OBJ_YAW), OBJ_AT)
    full = render_tags([(TABLE_ID, TABLE_SIZE, c_from_w @ table), (HAND_ID, TAG, c_from_w @ hand),
                        (OBJ_ID, TAG, c_from_w @ obj)], seed=1)
    empty = render_tags([(TABLE_ID, TABLE_SIZE, c_from_w @ table)], seed=2)
    video = d / "scene.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (W, H))
    assert writer.isOpened()
    for img in [full] * GOOD_FRAMES + [empty] * LOST_FRAMES:
        writer.write(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    writer.release()
    return video, save_calibration(d / "calib.json", calibration_from_intrinsics(K, (W, H)))


def _config(camera_files, ports: dict[str, str], **top):
    video, calib = camera_files
    cfg = example_rig_config("block_push")
    for name in ("r1", "r2"):
        # an arm the test does not connect (a SimArm stands in) still has a port of its own: one port for two arms
        # is refused
        cfg["arms"][name]["port"] = ports.get(name, f"/dev/unused-{name}")
    cfg["camera"].update({"source": str(video), "calibration": str(calib), "table_tag_size_m": TABLE_SIZE,
                          "tag_size_m": TAG, "table_tag_pose": dict(zip(("x_mm", "y_mm", "z_mm"), TABLE_AT_MM))})
    cfg.update({"control_period_s": 0.05, "max_lost_frames": 2, "reset_settle_s": 1.0, **top})
    return parse_rig_config(json.dumps(cfg))


def _world_end(cfg, name: str, angles) -> np.ndarray:
    """Flange in the world task plane (m), computed here from the base pose (yaw only) independently of rig.py."""
    b = cfg.arms[name].base
    p = kinematics.position(angles)
    c, s = math.cos(math.radians(b.yaw_deg)), math.sin(math.radians(b.yaw_deg))
    return np.array([b.x_mm + c * p[0] - s * p[1], b.y_mm + s * p[0] + c * p[1]]) / 1e3


def _sent_angles(fake: fm.FakeMyCobot) -> list[float]:
    return fm.decode_int16(fake.received(fm.SEND_ANGLES)[-1].payload[:12], 100.0)


def test_real_rig_y_observe_act_refuse_reset(camera_files) -> None:
    home = [float(a) for a in kinematics.home_angles("block_push")]
    with fm.FakeMyCobot("pty", angles=home) as f1, fm.FakeMyCobot("pty", angles=home) as f2:
        fakes = {"r1": f1, "r2": f2}
        # r1 may not go further than 20 mm to its left of its base (world x <= -40 mm): refused, not clipped
        cfg = _config(camera_files, {"r1": f1.device, "r2": f2.device}, clip_to_workspace=False)
        cfg = cfg.model_copy(update={"arms": {**cfg.arms, "r1": cfg.arms["r1"].model_copy(
            update={"workspace_min_mm": (140.0, -20.0, 90.0)})}})
        rig = RealRig(cfg, "Y")
        try:
            assert f1.count(fm.POWER_ON) == 1 and f2.count(fm.POWER_ON) == 1
            obs = rig.observe()
            assert obs.shape == (7,)
            for slot, name in enumerate(("r1", "r2")):
                assert np.linalg.norm(obs[2 * slot:2 * slot + 2] - _world_end(cfg, name, fakes[name].angles)) < 1e-3
            assert np.linalg.norm(obs[4:6] - np.array(OBJ_AT[:2])) < 0.005
            assert math.degrees(obs[6]) == pytest.approx(OBJ_YAW, abs=2.0)

            rel = {"r1": np.array([0.010, -0.005]), "r2": np.array([-0.004, 0.012])}
            rig.act(rel)
            for slot, name in enumerate(("r1", "r2")):
                assert fakes[name].count(fm.SEND_ANGLES) == 1
                moved = _world_end(cfg, name, _sent_angles(fakes[name])) - obs[2 * slot:2 * slot + 2]
                assert np.linalg.norm(moved - rel[name]) < 1e-3, (name, moved, rel[name])

            obs = rig.observe()
            for name in fakes:
                fakes[name].clear()
            refused = [
                ({"r1": [0.030, 0.0], "r2": [0.0, 0.005]}, r"r1: target .* is outside the workspace"),
                ({"r1": [0.0, 0.05], "r2": [0.0, 0.0]}, r"r1: relative target of 50\.0 mm is longer than"),
                ({"r1": [0.0, 0.0], "r2": [math.nan, 0.0]}, r"r2: relative target .* is not finite"),
            ]
            for targets, pattern in refused:
                with pytest.raises(SafetyError, match=pattern):
                    rig.act(targets)
            with pytest.raises(ValueError, match="domain Y commands"):
                rig.act({"r1": [0.0, 0.0]})
            assert f1.count(fm.SEND_ANGLES) == 0 and f2.count(fm.SEND_ANGLES) == 0  # nothing reached either arm

            obs = rig.reset()  # back to the start angles, in steps, then a fresh observation
            for name in fakes:
                np.testing.assert_allclose(_sent_angles(fakes[name]), home, atol=0.011)
            np.testing.assert_allclose(obs[:2], _world_end(cfg, "r1", home), atol=1e-3)
        finally:
            rig.close()


def test_real_rig_r1h_tracks_hand_and_stops_when_tracking_is_lost(camera_files) -> None:
    home = [float(a) for a in kinematics.home_angles("block_push")]
    with fm.FakeMyCobot("pty", angles=home) as f1:
        cfg = _config(camera_files, {"r1": f1.device})
        rig = RealRig(cfg, "R1H")  # only r1 is connected (r2's port is never opened)
        try:
            obs = rig.observe()
            np.testing.assert_allclose(obs[:2], _world_end(cfg, "r1", home), atol=1e-3)
            assert np.linalg.norm(obs[2:4] - np.array(HAND_AT[:2])) < 0.005
            assert np.linalg.norm(obs[4:6] - np.array(OBJ_AT[:2])) < 0.005
            for _ in range(GOOD_FRAMES - 1):
                rig.observe()
            assert f1.count(fm.STOP) == 0
            with pytest.raises(TrackingLost, match=r"3 frames .* \(the object and hand tags were not seen\)"):
                rig.observe()  # frames 5, 6, 7 lack the hand and object: 3 > max_lost_frames 2
            assert f1.count(fm.STOP) == 1
        finally:
            rig.close()


class _StillTracker:
    """A tracker that always sees the object at the origin (for rigs built on SimArm)."""

    def read(self) -> TrackedFrame:
        pose = ObjectPose(position=np.zeros(3), quaternion=np.array([1.0, 0, 0, 0]), yaw=0.0, pose=np.eye(4))
        return TrackedFrame(timestamp=0.0, frame_index=0, hand_position=None, object_pose=pose, lost=True,
                            table_seen=True)

    def close(self) -> None:
        pass


def test_targets_outside_the_workspace_are_clipped_by_default(camera_files) -> None:
    home = kinematics.home_angles("block_push")
    cfg = _config(camera_files, {})
    sim = SimArm(home, max_step_deg=180.0)
    rig = RealRig(cfg, "Y", arms={"r1": sim, "r2": SimArm(home, max_step_deg=180.0)}, tracker=_StillTracker())
    try:
        for _ in range(4):  # r1 walks to its left (world +x) until its base-frame y reaches workspace_min -50 mm
            rig.observe()
            rig.act({"r1": [0.035, 0.0], "r2": [0.0, 0.0]})
        flange = kinematics.position(sim.angles)
        # clipped CLIP_MARGIN_MM inside the edge, so that the arm never rests where the safety box refuses it
        assert flange[1] == pytest.approx(-50.0 + CLIP_MARGIN_MM, abs=0.1)
        assert flange[2] == pytest.approx(100.0, abs=0.1)
    finally:
        rig.close()


def test_random_recording_on_the_example_rig_completes(camera_files, tmp_path) -> None:
    """Random targets run into the workspace's edges; clipped inside them, no command or reset is refused there
    (clipped onto the edge itself, the first episode used to end with 'y = -50.0 mm below the workspace minimum
    -50.0 mm' and the next reset was refused)."""
    home = kinematics.home_angles("block_push")
    cfg = _config(camera_files, {}, control_period_s=0.001, reset_settle_s=0.5)
    rig = RealRig(cfg, "Y", arms={"r1": SimArm(home), "r2": SimArm(home)}, tracker=_StillTracker())
    rec = EpisodeRecorder(tmp_path / "random_Y", twin_common.twin_schema("block_push", "Y", "random", {}), 0.1)
    try:
        for ep in range(4):
            rig.reset(seed=ep)
            rec.start()
            record_random_episode(rig, rec, np.random.default_rng(ep), 30, 0.008, 3)
    finally:
        rig.close()
    assert len(read_recording(tmp_path / "random_Y")) == 4 * 30


def test_a_recording_folder_holds_one_domain_and_task(tmp_path, capsys) -> None:
    out = tmp_path / "rec"
    EpisodeRecorder(out, twin_common.twin_schema("block_push", "Y", "random", {}), 0.1)
    EpisodeRecorder(out, twin_common.twin_schema("block_push", "Y", "random", {"seed": 1}), 0.1)  # same: resumes
    with pytest.raises(RecordingMismatch, match=r"holds a recording of domain 'Y', not 'R1H'"):
        EpisodeRecorder(out, twin_common.twin_schema("block_push", "R1H", "random", {}), 0.1)
    with pytest.raises(RecordingMismatch, match=r"task 'block_push', not 'peg_insertion'"):
        EpisodeRecorder(out, twin_common.twin_schema("peg_insertion", "Y", "random", {}), 0.1)
    args = ["record-random", "--sim", "--task", "block_push", "--domain", "HR2", "--episodes", "1", "--steps", "2",
            "--out", str(out)]
    assert main(args) == 2
    assert "holds a recording of domain 'Y', not 'HR2'" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["record-random", "--domain", "Y", "--episodes", "-3", "--steps", "2"], "--episodes: -3 is not a positive count"),
    (["record-random", "--domain", "Y", "--episodes", "1", "--steps", "0"], "--steps: 0 is not a positive count"),
    (["record-random", "--domain", "Y", "--episodes", "1", "--steps", "2", "--reach", "inf"],
     "--reach: inf is not a positive finite number"),
    (["record-random", "--domain", "Y", "--episodes", "1", "--steps", "10000000000"],
     "--steps: 10000000000 is more than the 100000 control steps an episode may have"),
    (["record-demos", "--pairing", "R1H", "--episodes", "1", "--steps", "100001"],
     "--steps: 100001 is more than the 100000 control steps"),
    (["record-demos", "--pairing", "R1H", "--episodes", "2", "--max-attempts", "0"],
     "--max-attempts: 0 is not a positive count"),
    (["deploy", "--task", "block_push", "--method", "lfdt", "--models", "m", "--log", "l.csv", "--trials", "0"],
     "--trials: 0 is not a positive count"),
])
def test_counts_are_checked_where_they_enter(argv, message, capsys) -> None:
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args([*argv, "--sim", "--out", "x"] if argv[0] != "deploy" else [*argv, "--sim"])
    assert e.value.code == 2 and message in capsys.readouterr().err


def test_deploy_without_trained_models_names_the_folder(tmp_path, capsys) -> None:
    args = ["deploy", "--sim", "--task", "block_push", "--method", "lfdt", "--models", str(tmp_path / "none"),
            "--log", str(tmp_path / "log.csv"), "--trials", "1"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"--models {tmp_path / 'none'}: no trained lfdt policy" in err and "Traceback" not in err
    assert not (tmp_path / "log.csv").exists()


# ------------------------------------------------------------------------------------------------ calibrate


def _write_video(path: Path, frames: list[np.ndarray]) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (W, H))
    assert writer.isOpened()
    for img in frames:
        writer.write(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    writer.release()
    return path


def test_calibrate_from_a_chessboard_video(tmp_path: Path, capsys) -> None:
    from test_tracker import _board_views, _chessboard_texture

    squares, px, margin, sq = (10, 7), 60, 60, 0.025  # 9x6 inner corners
    m = sq * margin / px
    views = _board_views(_chessboard_texture(squares, px, margin), squares[0] * sq + 2 * m,
                         squares[1] * sq + 2 * m, K, n=8, seed=4)
    video = _write_video(tmp_path / "board.avi", views)
    out = tmp_path / "calib.json"
    args = ["calibrate", "--camera", str(video), "--pattern", "9", "6", "--square", str(sq), "--every", "0",
            "--out", str(out)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "RMS reprojection error" in text
    calib = json.loads(out.read_text())
    assert calib["method"] == "chessboard" and calib["n_views"] >= 6 and calib["rms_px"] < 1.0
    assert calib["camera_matrix"][0][0] == pytest.approx(K[0, 0], rel=0.03)
    # a video without the board: nothing saved, exit 2 with the reason
    blank = _write_video(tmp_path / "blank.avi", [np.full((H, W), 128, np.uint8)] * 3)
    assert main([*args[:2], str(blank), *args[3:-1], str(tmp_path / "none.json")]) == 2
    assert "was usable in 0 views (0 frames grabbed), 6 needed" in capsys.readouterr().err
    assert not (tmp_path / "none.json").exists()
