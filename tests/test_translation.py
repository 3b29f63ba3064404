"""Translator: ablations are weights at zero, skips convert units right, L_id is on the real robot only,
the replay check measures physical consistency, outputs follow the data conventions."""

import numpy as np
import pytest
import torch

from lfdt import data, layout, translation
from lfdt.config import EnvConfig, RandomConfig, TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.random_motion import collect_random


def test_methods_are_weights_at_zero():
    base = TranslatorConfig(lambda_dyn=7.0, lambda_id=3.0)
    assert translation.method_config("lfdt", base) == base
    assert translation.method_config("lfdt_no_dyn", base).lambda_dyn == 0 and \
        translation.method_config("lfdt_no_dyn", base).lambda_id == 3.0
    assert translation.method_config("lfdt_no_id", base).lambda_id == 0
    with pytest.raises(ValueError, match="unknown translator method"):
        translation.method_config("lfdt_magic", base)


def test_canonical_columns_and_robot_slot():
    for p in layout.PAIRINGS:
        cols = translation.canonical_x_columns(p)
        assert cols[:8] == layout.arm_columns(layout.robot_arm(p)) and cols[8:18] == layout.arm_columns("h")
        y = layout.state_columns("Y")
        assert y[layout.BOX_PUSH.robot_y_slice(p)] == layout.arm_columns(layout.robot_arm(p))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("tr")
    env = EnvConfig()
    paths = {}
    for d in layout.DOMAINS:
        table, _ = collect_random(d, env, RandomConfig(transitions=2_000, episodes_per_batch=20))
        paths[d] = data.write_table(table, root / f"{d}.parquet")
    dyn = DynamicsModels(19, 6, [32, 32])
    y = data.read_transitions(paths["Y"])
    dyn.y_norm.mean.copy_(torch.as_tensor(y[[f"state.{c}" for c in layout.state_columns("Y")]].mean().to_numpy()))
    dyn.y_norm.std.copy_(torch.as_tensor(y[[f"state.{c}" for c in layout.state_columns("Y")]].std().to_numpy()))
    return env, paths, dyn


def test_skips_put_hand_and_object_where_they_belong(tiny):
    env, paths, dyn = tiny
    random_x = {p: translation.load_x_transitions(paths[p], p) for p in layout.PAIRINGS}
    tr = translation.Translator([16])
    translation.fit_x_normalizers(tr, dyn, random_x, 1e-2, object_mode="correct", hand_skip=True)
    torch.nn.init.zeros_(tr.G[-1].weight)
    torch.nn.init.zeros_(tr.G[-1].bias)  # G's own output is 0: only the skips remain
    y_cols = layout.state_columns("Y")
    for p in layout.PAIRINGS:
        x = random_x[p].x[:5]
        y = dyn.y_norm.inverse(tr.translate(x, p)).numpy()
        cols = translation.canonical_x_columns(p)
        missing = "r2" if layout.robot_arm(p) == "r1" else "r1"
        np.testing.assert_allclose(y[:, y_cols.index(f"{missing}.ee_x")], x[:, cols.index("h.ee_x")], atol=1e-5)
        np.testing.assert_allclose(y[:, y_cols.index("box.yaw")], x[:, cols.index("box.yaw")], atol=1e-5)
        # the real robot has no skip: its columns are G's (zero) output, i.e. the mean
        np.testing.assert_allclose(y[:, y_cols.index(f"{layout.robot_arm(p)}.q0")],
                                   float(dyn.y_norm.mean[y_cols.index(f"{layout.robot_arm(p)}.q0")]), atol=1e-5)


def test_identity_loss_pulls_the_real_robot_only(tiny):
    env, paths, dyn = tiny
    random_x = {p: translation.load_x_transitions(paths[p], p) for p in layout.PAIRINGS}
    cfg = TranslatorConfig(iterations=300, hidden=[64, 64], lambda_adv=0.0, lambda_dyn=0.0, lambda_id=1.0,
                           log_every=100, batch_size=32)
    tr, stats = translation.train_translator(random_x, random_x, np.zeros((10, 19), np.float32), dyn, cfg, seed=0)
    assert [c["iteration"] for c in stats["curve"]] == [100, 200, 300]
    assert stats["curve"][-1]["loss/id"] < 0.5 * stats["curve"][0]["loss/id"]
    assert stats["curve"][-1]["loss/dyn"] > 0 and stats["curve"][-1]["loss/adv"] > 0  # measured, not trained


def test_replay_of_true_transitions_is_consistent(tiny):
    """Replaying Y's own recorded actions from Y's own start states reproduces the final box pose."""
    env, paths, _ = tiny
    df = data.read_transitions(paths["Y"])
    df = df[df.episode_index < 3]
    res = translation.replay_check(df, env)
    assert res["replayed_demos"] == 3
    assert res["replay_box_position_error_m"] < 1e-6 and res["replay_box_yaw_error_rad"] < 1e-6
    shuffled = df.copy()
    acts = [f"action.{c}" for c in layout.action_columns("Y")]
    shuffled[acts] = -shuffled[acts].to_numpy()
    assert translation.replay_check(shuffled, env)["replay_box_position_error_m"] > 1e-4
