"""The MuJoCo twin of the real tasks: servo-like arms, a different human hand, tasks that need both arms."""

import numpy as np
import pytest

from lfdt import data, layout
from lfdt.rig.recording import EpisodeRecorder, read_recording
from lfdt.tasks import registry
from lfdt.tasks.demonstrators import TwinDemonstrator
from lfdt.tasks.planar_env import TwinConfig, TwinEnv
from lfdt.twin import collect as twin_collect
from lfdt.twin import common as twin_common


def run(env, policy, seed):
    obs, info = env.reset(seed=seed)
    steps, done = 0, False
    while not done:
        obs, _, term, trunc, info = env.step(policy(obs))
        steps, done = steps + 1, term or trunc
    return info, steps, obs


@pytest.mark.parametrize("task", registry.PLANAR)
@pytest.mark.parametrize("pairing", layout.PAIRINGS)
def test_scripted_demonstrations_succeed(task, pairing):
    ok = 0
    for seed in range(10):
        env = TwinEnv(task, pairing)
        env.reset(seed=seed)
        demo = TwinDemonstrator(env)
        info, steps, _ = run(env, demo, seed)
        ok += info["is_success"]
    assert ok >= 9


def test_robot_end_follows_target_with_speed_limit_and_lag():
    env = TwinEnv("block_push", "Y")
    obs, _ = env.reset(seed=0)
    start = obs[:2].copy()
    far = np.array([0.0, 0.05, 0.0, 0.0])  # 5 cm ahead in one command: more than one step of travel
    obs, *_ = env.step(far)
    moved = obs[1] - start[1]
    limit = env.cfg.robot_speed * env.cfg.control_dt
    assert 0 < moved <= limit + 1e-4
    for _ in range(3):
        obs, *_ = env.step(np.zeros(4))
    assert obs[1] - start[1] == pytest.approx(limit, abs=2e-3)  # the lagging end settles on its setpoint


def test_human_hand_differs_from_a_robot_end():
    cfg = TwinConfig()
    assert cfg.human_speed > 1.5 * cfg.robot_speed and cfg.human_noise > 0
    bp = TwinEnv("block_push", "R1H")
    assert bp.model.geom("hand").type == 2  # a sphere, where the robot has a finger cylinder
    # the person holds the peg further from its centre and tilted: same hand, other object pose
    robot = TwinEnv("peg_insertion", "Y")
    human = TwinEnv("peg_insertion", "R1H")
    o_r, _ = robot.reset(seed=3)
    o_h, _ = human.reset(seed=3)
    assert np.allclose(o_r[2:4], o_h[2:4], atol=0.01)  # the holding end starts at the same place
    assert abs((o_h[4] - o_h[2]) - (o_r[4] - o_r[2])) > 0.01  # but the peg sits elsewhere relative to it
    assert abs(o_h[6] - o_r[6]) > 0.02


def test_block_push_needs_both_arms():
    env = TwinEnv("block_push", "Y")
    env.reset(seed=1)
    one_arm = np.array([0.0, 0.006, 0.0, 0.0])
    info, _, obs = run(env, lambda o: one_arm, 1)
    assert not info["is_success"] and abs(obs[6]) > 0.2  # pushed at one end, the block turns


def test_peg_insertion_needs_alignment():
    env = TwinEnv("peg_insertion", "Y")
    straight = np.array([0.0, 0.0, 0.006, 0.0])  # the peg goes straight ahead, the receptacle waits

    info, _, _ = run(env, lambda o: straight, 2)
    height_gap = abs(env.data.site("peg_tip").xpos[2] - env.data.site("slot_mouth").xpos[2])
    assert not info["is_success"] or height_gap < 0.003


def test_same_seed_same_trajectory():
    def roll():
        env = TwinEnv("peg_insertion", "HR2")
        obs, _ = env.reset(seed=5)
        demo = TwinDemonstrator(env)
        out = [obs]
        for _ in range(10):
            obs, *_ = env.step(demo(obs))
            out.append(obs)
        return np.array(out)

    np.testing.assert_array_equal(roll(), roll())


def test_recordings_follow_the_data_conventions(tmp_path):
    n = twin_collect.record_random("block_push", "R1H", 95, 30, 0, tmp_path / "random_R1H")
    assert n == 95
    meta = data.check_transitions(tmp_path / "random_R1H", "random", "R1H", registry.get("block_push").layout)
    assert meta["task"] == "block_push"
    df = read_recording(tmp_path / "random_R1H")
    assert len(df) == 95 and df.episode_index.nunique() == 4
    assert list(df.columns[:3]) == ["episode_index", "frame_index", "timestamp"]
    stats = twin_collect.record_demos("peg_insertion", "HR2", 3, 0, tmp_path / "demos_HR2")
    assert stats["demonstrations"] == 3
    df = data.read_transitions(tmp_path / "demos_HR2")
    assert [c for c in df.columns if c.startswith("action.")] == ["action.r2.dx", "action.r2.dz"]


def test_recorder_writes_only_finished_episodes(tmp_path):
    schema = twin_common.twin_schema("block_push", "Y", "random", {})
    rec = EpisodeRecorder(tmp_path, schema, 0.1)
    rec.start()
    for _ in range(3):
        rec.add(np.zeros(7), np.zeros(4), np.ones(7))
    first = rec.finish()
    rec.start()
    rec.add(np.zeros(7), np.zeros(4), np.ones(7))  # never finished: nothing on disk
    assert sorted(p.name for p in tmp_path.glob("*.parquet")) == [first.name]
    assert rec.next_index() == 1


def test_random_motion_of_block_push_starts_along_the_push():
    from lfdt.rig.sim import SimRig
    from lfdt.tasks.block_push import RANDOM_MOTION_ADVANCE

    env = TwinEnv("block_push", "Y")
    advances = []
    for seed in range(30):
        start, _ = env.reset(seed=seed)
        moved, _ = env.reset(seed=seed, options={"random_motion": True})
        advance = moved[5] - start[5]  # obj.y
        np.testing.assert_allclose(moved[[1, 3]] - start[[1, 3]], advance, atol=1e-9)  # both ends moved with it
        np.testing.assert_allclose(moved[[0, 2, 4, 6]], start[[0, 2, 4, 6]], atol=1e-9)
        advances.append(advance)
    assert 0 <= min(advances) and max(advances) <= RANDOM_MOTION_ADVANCE and np.std(advances) > 0.02
    # the random person's rig records random motion, so it starts there; the scripted person's does not
    with SimRig("block_push", "R1H", human="random") as rig, SimRig("block_push", "R1H") as demo_rig:
        assert rig.reset(seed=3)[5] > demo_rig.reset(seed=3)[5]
    # a task that says nothing starts its random motion where its episodes start
    peg = TwinEnv("peg_insertion", "Y")
    np.testing.assert_array_equal(peg.reset(seed=4)[0], peg.reset(seed=4, options={"random_motion": True})[0])
