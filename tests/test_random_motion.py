"""Random-motion collection: same states as the Gymnasium path, documented schema, reproducible."""

import numpy as np
import pyarrow.parquet as pq
import pytest

from lfdt import data, layout
from lfdt.config import EnvConfig, RandomConfig
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push.env import BoxPushEnv
from lfdt.tasks.box_push.random_motion import collect_random, random_commands, rollout_episodes

CFG = EnvConfig()


@pytest.mark.parametrize("domain", layout.DOMAINS)
def test_rollout_matches_gymnasium_env(domain):
    env = BoxPushEnv(domain, CFG)
    rng = np.random.default_rng(5)
    q0 = np.stack([env.scene.sample_initial_qpos(rng) for _ in range(3)])
    acts = np.stack([random_commands(rng, 40, env.scene.act_dim, RandomConfig()) for _ in range(3)])
    obs, _ = rollout_episodes(env.scene, q0, acts, threads=2)
    for b in range(3):
        o, _ = env.reset(options={"qpos": q0[b]})
        ref = [o] + [env.step(a)[0] for a in acts[b]]
        np.testing.assert_allclose(obs[b], np.array(ref), atol=1e-10)


def test_commands_are_held_and_bounded():
    cfg = RandomConfig(hold_min=3, hold_max=3, amplitude=0.5)
    a = random_commands(np.random.default_rng(0), 30, 4, cfg)
    assert np.abs(a).max() <= 0.5
    assert np.all(a[0] == a[1]) and np.all(a[1] == a[2]) and not np.all(a[2] == a[3])


def test_collect_random_table(tmp_path):
    cfg = RandomConfig(transitions=1_050, episode_steps=100, episodes_per_batch=4, threads=2)
    table, stats = collect_random("HR2", CFG, cfg)
    assert table.num_rows == 1_050 and stats["episodes"] == 11
    path = data.write_table(table, tmp_path / "HR2.parquet")
    meta = data.check_transitions(path, "random", "HR2", box_columns.BOX_PUSH)
    assert meta["seed"] == 0 and meta["env"]["frame_skip"] == CFG.frame_skip
    assert meta["layout"]["domains"]["HR2"]["state"] == box_columns.state_columns("HR2")
    df = data.read_transitions(path)
    # consecutive rows of an episode chain: next_state(t) == state(t+1)
    s = df[[layout.STATE_PREFIX + c for c in box_columns.state_columns("HR2")]].to_numpy()
    ns = df[[layout.NEXT_STATE_PREFIX + c for c in box_columns.state_columns("HR2")]].to_numpy()
    same_ep = df.episode_index.to_numpy()[1:] == df.episode_index.to_numpy()[:-1]
    np.testing.assert_allclose(ns[:-1][same_ep], s[1:][same_ep])
    assert df.frame_index.max() == 99 and df.timestamp.iloc[1] == pytest.approx(CFG.timestep * CFG.frame_skip)
    # the box does get pushed in random data (otherwise a dynamics model could not learn contact)
    moved = np.linalg.norm(ns[:, -3:-1] - s[:, -3:-1], axis=1)
    assert (moved > 1e-3).mean() > 0.05
    field = pq.read_schema(path).field("state.h.q0")
    assert b"Human" in field.metadata[b"description"] and field.metadata[b"unit"] == b"rad"
    # reproducible
    again, _ = collect_random("HR2", CFG, cfg)
    assert again.equals(table)


def test_readers_refuse_the_wrong_kind_of_data_and_name_corrupt_files(tmp_path):
    cfg = RandomConfig(transitions=200, episode_steps=100, episodes_per_batch=2, threads=1)
    table, _ = collect_random("R1H", CFG, cfg)
    path = data.write_table(table, tmp_path / "R1H.parquet")
    from lfdt.translation.transitions import load_x_transitions

    # a random-motion file handed over as demonstrations is refused before anything trains on it
    with pytest.raises(data.DataFileError, match=r"R1H.parquet holds random data of domain R1H \(kind 'random' "
                                                 r"where 'demos' is needed\)"):
        load_x_transitions(path, "R1H", kind="demos", tl=box_columns.BOX_PUSH)
    with pytest.raises(data.DataFileError, match=r"domain 'R1H' where 'HR2' is needed"):
        data.read_transitions(path, kind="random", domain="HR2")
    with pytest.raises(data.DataFileError, match=r"task 'box_push' where 'block_push' is needed"):
        data.read_transitions(path, task="block_push")
    assert len(load_x_transitions(path, "R1H", kind="random", tl=box_columns.BOX_PUSH).x) == 200
    # corrupted bytes: the error names the file
    bad = tmp_path / "bad.parquet"
    raw = path.read_bytes()
    bad.write_bytes(raw[:200] + bytes(4000) + raw[4200:])
    with pytest.raises(data.DataFileError, match=r"bad.parquet: not a readable Parquet file"):
        data.read_transitions(bad)


def test_pushing_episodes_push_the_box_and_the_default_data_is_unchanged():
    """random.push_fraction: pushing episodes move the box much further than uniform commands do; at 0 the commands
    are those of the plain random motion (the generator draws nothing more)."""
    from lfdt.tasks.box_push.env import BoxPushModel
    from lfdt.tasks.box_push.random_motion import episode_commands, push_commands, random_commands, rollout_episodes

    scene = BoxPushModel("Y", EnvConfig())
    cfg = RandomConfig(episode_steps=60, push_fraction=0.0)
    for ep in range(3):
        a, b = np.random.default_rng(ep), np.random.default_rng(ep)
        q0 = scene.sample_initial_qpos(a)
        scene.sample_initial_qpos(b)
        np.testing.assert_array_equal(episode_commands(scene, q0, a, cfg), random_commands(b, 60, scene.act_dim, cfg))
    moved = {}
    for kind in ("random", "push"):
        q0s, acts = [], []
        for ep in range(20):
            rng = np.random.default_rng(100 + ep)
            q0s.append(scene.sample_initial_qpos(rng))
            acts.append(push_commands(scene, q0s[-1], rng, 60, cfg) if kind == "push"
                        else random_commands(rng, 60, scene.act_dim, cfg))
        obs, _ = rollout_episodes(scene, np.array(q0s), np.array(acts))
        moved[kind] = float(np.mean(obs[:, -1, -2] - obs[:, 0, -2]))  # box y travelled
        assert np.abs(np.array(acts)).max() <= 1.0
    assert moved["push"] > 0.04 and moved["push"] > 3 * abs(moved["random"]), moved
