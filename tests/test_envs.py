"""Physical facts of the box-push task, not just shapes."""

import gymnasium as gym
import mujoco
import numpy as np
import pytest

from lfdt import layout
from lfdt.config import EnvConfig
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push.env import ENV_IDS, BoxPushEnv, BoxPushModel, forward_kinematics, inverse_kinematics
from lfdt.tasks.box_push.scripted import ScriptedPush, run_scripted

CFG = EnvConfig()
# a start without noise, so the scripted pushes test physics and not the luck of a draw
QUIET = CFG.model_copy(update={"joint_noise": 0.0,
                               "box": CFG.box.model_copy(update={"start_noise_xy": 0.0, "start_noise_yaw": 0.0})})
TOP_SPEED = 0.12  # m/s: about the robot's top end-effector speed in the start pose


@pytest.fixture(params=layout.DOMAINS)
def domain(request):
    return request.param


def test_registered_and_layout(domain):
    env = gym.make(ENV_IDS[domain])
    obs, info = env.reset(seed=3)
    assert obs.shape == (len(box_columns.state_columns(domain)),)
    assert env.action_space.shape == (len(box_columns.action_columns(domain)),)
    assert {"is_success", "box_distance", "box_yaw", "box_speed"} <= set(info)
    # the observation's named columns are what they say they are
    cols = box_columns.state_columns(domain)
    unwrapped = env.unwrapped
    assert obs[cols.index("box.x")] == pytest.approx(unwrapped.data.qpos[unwrapped.scene.box_qpos][0])
    assert obs[cols.index("box.yaw")] == pytest.approx(unwrapped.data.qpos[unwrapped.scene.box_qpos][2])
    a1 = layout.DOMAIN_ARMS[domain][0]
    ee = unwrapped.data.site(f"{a1}_tip").xpos[:2]
    assert obs[cols.index(f"{a1}.ee_x")] == pytest.approx(ee[0], abs=1e-9)
    assert obs[cols.index(f"{a1}.ee_y")] == pytest.approx(ee[1], abs=1e-9)
    env.close()


def test_start_pose_touches_box(domain):
    env = BoxPushEnv(domain, CFG)
    for seed in range(20):
        _, info = env.reset(seed=seed)
        assert max(info["contact_distance"]) < CFG.start_gap + 0.03


def test_same_seed_same_trajectory(domain):
    def roll(seed):
        env = BoxPushEnv(domain, CFG)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        traj = [obs]
        for _ in range(30):
            traj.append(env.step(rng.uniform(-1, 1, env.action_space.shape))[0])
        return np.array(traj)

    np.testing.assert_array_equal(roll(7), roll(7))
    assert not np.array_equal(roll(7), roll(8))


def test_coordinated_two_arm_push_succeeds_and_moves_box_to_goal():
    env = BoxPushEnv("Y", QUIET)
    r = run_scripted(env, ScriptedPush(speeds=(TOP_SPEED, TOP_SPEED)))
    start, end = r["box"][0], r["box"][-1]
    goal = np.asarray(QUIET.box.goal)
    assert np.linalg.norm(end[:2] - goal) < np.linalg.norm(start[:2] - goal) - 0.1
    assert r["success"]
    # quasi-static: even at top speed the push takes longer than 20 control steps
    assert len(r["box"]) - 1 >= 20


@pytest.mark.parametrize("domain", ["Y", "R1H", "HR2"])
def test_one_arm_at_half_speed_fails(domain):
    env = BoxPushEnv(domain, QUIET)
    r = run_scripted(env, ScriptedPush(speeds=(TOP_SPEED, TOP_SPEED / 2)))
    assert not r["success"]
    assert np.abs(r["box"][:, 2]).max() > QUIET.success.yaw


@pytest.mark.parametrize("domain", ["Y", "R1H", "HR2"])
def test_one_arm_starting_late_fails(domain):
    env = BoxPushEnv(domain, QUIET)
    r = run_scripted(env, ScriptedPush(speeds=(TOP_SPEED, TOP_SPEED), delays=(0.0, 0.2)))
    assert not r["success"]
    assert np.abs(r["box"][:, 2]).max() > QUIET.success.yaw


def test_one_arm_push_rotates_box():
    env = BoxPushEnv("Y", QUIET)
    r = run_scripted(env, ScriptedPush(speeds=(TOP_SPEED, 0.0)), steps=40)
    box = r["box"]
    assert abs(box[-1, 2]) > 0.5  # turned by more than 0.5 rad
    assert not r["success"]


def test_arms_never_touch_each_other():
    """Arms collide with the box only: with random flailing no contact between the two arms ever exists."""
    env = BoxPushEnv("R1H", CFG)
    m, d = env.model, env.data
    arm_of = {}
    for g in range(m.ngeom):
        body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, m.geom_bodyid[g]) or ""
        arm_of[g] = body.split("_")[0] if body.split("_")[0] in ("r1", "r2", "h") else None
    rng = np.random.default_rng(1)
    env.reset(seed=1)
    box_contacts = 0
    for _ in range(400):
        env.step(rng.uniform(-1, 1, env.action_space.shape))
        for c in d.contact[: d.ncon]:
            a, b = arm_of[c.geom1], arm_of[c.geom2]
            assert not (a and b and a != b), f"contact between arms {a} and {b}"
            box_contacts += (a is None) != (b is None)
    assert box_contacts > 0  # the arms do touch the box


def test_success_fires_exactly_when_all_conditions_hold():
    scene = BoxPushModel("Y", CFG)
    s = CFG.success
    gx, gy = CFG.box.goal
    ok = np.array([gx, gy, 0.0])
    assert scene.success(ok, 0.0)
    assert scene.success(np.array([gx + 0.99 * s.distance, gy, 0.99 * s.yaw]), 0.99 * s.speed)
    assert not scene.success(np.array([gx + 1.01 * s.distance, gy, 0.0]), 0.0)  # too far
    assert not scene.success(np.array([gx, gy, 1.01 * s.yaw]), 0.0)  # turned
    assert not scene.success(np.array([gx, gy, -1.01 * s.yaw]), 0.0)
    assert not scene.success(ok, 1.01 * s.speed)  # still moving
    # and through the environment: box placed at the goal, at rest -> success; moving -> not
    env = BoxPushEnv("Y", CFG)
    env.reset(seed=0)
    qpos = env.data.qpos.copy()
    qpos[scene.box_qpos] = ok
    env.set_state(qpos)
    assert env._info()["is_success"]
    qvel = np.zeros_like(qpos)
    qvel[scene.box_qpos.start + 1] = 2 * s.speed
    env.set_state(qpos, qvel)
    assert not env._info()["is_success"]


def test_episode_terminates_on_success_and_truncates_at_limit():
    env = BoxPushEnv("Y", QUIET)
    r = run_scripted(env, ScriptedPush(speeds=(TOP_SPEED, TOP_SPEED)))
    assert r["infos"][-1]["is_success"]
    r = run_scripted(env, ScriptedPush(speeds=(0.0, 0.0)))
    assert len(r["box"]) - 1 == QUIET.max_episode_steps


def test_human_differs_from_robot_beyond_link_count():
    """Reach, strength and speed of the human stand-in differ from a robot's, as a person's arm does."""
    r, h = CFG.robot, CFG.human
    assert len(h.links) == 4 and len(r.links) == 3
    assert abs(sum(h.links) - sum(r.links)) > 0.02  # reach
    assert h.gears[0] > 1.3 * r.gears[0]  # strength at the shoulder
    top = lambda arm: np.array(arm.gears[:3]) / np.array(arm.damping[:3])  # noqa: E731 - joint top speeds
    assert np.all(top(h) > 1.5 * top(r))  # speed
    assert h.tip_radius != r.tip_radius  # contact shape
    # a human pushing at its own pace next to a robot turns the box: the pairing must adapt
    env = BoxPushEnv("R1H", QUIET)
    r_fast = run_scripted(env, ScriptedPush(speeds=(TOP_SPEED, 2 * TOP_SPEED)))
    assert not r_fast["success"]


def test_ik_round_trip(domain):
    env = BoxPushEnv(domain, CFG)
    for arm in env.scene.arms:
        for target in ([arm.base[0] * 0.3, 0.2], [arm.base[0] * 0.2, 0.27]):
            q = inverse_kinematics(arm, np.array(target), 0.0)
            np.testing.assert_allclose(forward_kinematics(arm, q), target, atol=1e-9)


def test_render_rgb_array():
    env = BoxPushEnv("HR2", CFG, render_mode="rgb_array", width=96, height=96)
    env.reset(seed=0)
    img = env.render()
    assert img.shape == (96, 96, 3) and img.dtype == np.uint8 and img.std() > 5
    env.close()


def test_action_rate_penalty_is_the_change_of_command():
    base = CFG.model_copy(update={"reward": CFG.reward.model_copy(update={"w_action_rate": 0.0})})
    rated = CFG.model_copy(update={"reward": CFG.reward.model_copy(update={"w_action_rate": 2.0})})
    a1, a2 = np.full(6, 0.3), np.r_[np.full(3, -0.2), np.full(3, 0.5)]
    rewards = []
    for cfg in (base, rated):
        env = BoxPushEnv("Y", cfg)
        env.reset(seed=4)
        rewards.append([env.step(a1)[1], env.step(a2)[1]])
    # the first command changes from rest (zero), the second from the first
    assert rewards[0][0] - rewards[1][0] == pytest.approx(2.0 * float(a1 @ a1))
    assert rewards[0][1] - rewards[1][1] == pytest.approx(2.0 * float((a2 - a1) @ (a2 - a1)))


def test_path_rule_fails_an_episode_whose_box_turned_on_the_way():
    """The end-state rule sees only the last step; the path rule also remembers how far the box turned on the way,
    against a limit of max(|start yaw|, success.yaw) + success.path_yaw_margin."""
    scene = BoxPushModel("Y", CFG)
    s = CFG.success
    gx, gy = CFG.box.goal
    env = BoxPushEnv("Y", CFG)
    for start_yaw, detour, allowed in ((0.0, s.yaw + 1.5 * s.path_yaw_margin, False),
                                       (0.0, s.yaw + 0.5 * s.path_yaw_margin, True),
                                       (-0.22, 0.22 + 0.5 * s.path_yaw_margin, True),
                                       (-0.22, 0.22 + 1.5 * s.path_yaw_margin, False)):
        env.reset(seed=0)
        qpos = env.data.qpos.copy()
        qpos[scene.box_qpos] = [0.0, 0.22, start_yaw]
        env.set_state(qpos)
        assert env._info()["max_abs_yaw"] == pytest.approx(abs(start_yaw))
        env.data.qpos[scene.box_qpos.start + 2] = detour  # the box turned on the way
        mujoco.mj_forward(env.model, env.data)
        assert not env._info()["is_path_success"]  # not at the goal yet
        env.data.qpos[scene.box_qpos] = [gx, gy, 0.0]  # then arrived straight and at rest
        mujoco.mj_forward(env.model, env.data)
        info = env._info()
        assert info["is_success"], "the end-state rule does not look at the way"
        assert info["is_path_success"] is allowed, (start_yaw, detour)
        assert info["max_abs_yaw"] == pytest.approx(detour)
    # a new episode forgets the last one's detour
    env.reset(seed=0)
    assert env._info()["max_abs_yaw"] <= CFG.box.start_noise_yaw


def test_a_late_arm_that_catches_up_passes_the_end_state_rule_only():
    """Both arms push the same distance, one starting late: the box turns on the way, then mostly straightens (what
    two robots' programs of different timing do together): the end-state rule counts it, the path rule does not.
    Starting one step late instead stays within the path rule's margin."""
    from lfdt.tasks.box_push.env import jacobian

    def push(late_steps: int) -> dict:
        env = BoxPushEnv("Y", QUIET)
        n1 = env.scene.nq_arm[0]
        slots = (slice(0, n1), slice(n1, 2 * n1))
        env.reset(seed=0)
        end_y = [forward_kinematics(arm, env.data.qpos[sl])[1] + 0.12 for arm, sl in zip(env.scene.arms, slots)]
        for t in range(QUIET.max_episode_steps):
            u = []
            for i, (arm, sl) in enumerate(zip(env.scene.arms, slots)):
                q = env.data.qpos[sl]
                ee = forward_kinematics(arm, q)
                vy = 0.0 if (i == 1 and t < late_steps) else float(np.clip(4.0 * (end_y[i] - ee[1]), -0.1, 0.1))
                u.append(np.asarray(arm.cfg.damping) * (np.linalg.pinv(jacobian(arm, q)) @ np.array([0.0, vy]))
                         / np.asarray(arm.cfg.gears))
            _, _, term, trunc, info = env.step(np.clip(np.concatenate(u), -1, 1))
            if term or trunc:
                return info
        return info

    late = push(5)
    assert late["is_success"] and not late["is_path_success"]
    assert late["max_abs_yaw"] > QUIET.success.yaw + QUIET.success.path_yaw_margin
    in_step = push(1)
    assert in_step["is_success"] and in_step["is_path_success"]
