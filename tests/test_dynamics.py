"""Forward/inverse dynamics: episode-level split, learning beats the trivial predictors, saved and loaded alike."""

import numpy as np
import pytest
import torch

from lfdt import data
from lfdt.config import DynamicsConfig, EnvConfig, RandomConfig
from lfdt.dynamics import DynamicsModels, RandomY, fit_dynamics, load_models, load_random_y, split_episodes
from lfdt.errors import StageError
from lfdt.nets import load_state, save_state
from lfdt.tasks.box_push.columns import BOX_PUSH
from lfdt.tasks.box_push.random_motion import collect_random


@pytest.fixture(scope="module")
def random_y(tmp_path_factory):
    table, _ = collect_random("Y", EnvConfig(), RandomConfig(transitions=6_000, episodes_per_batch=20))
    path = data.write_table(table, tmp_path_factory.mktemp("dyn") / "Y.parquet")
    return load_random_y(path, BOX_PUSH)


def test_split_keeps_episodes_whole():
    ep = np.repeat(np.arange(50), 7)
    train, val = split_episodes(ep, 0.2, seed=0)
    assert not set(ep[train]) & set(ep[val]) and len(set(ep[val])) == 10


def test_fit_beats_trivial_predictors_and_round_trips(random_y, tmp_path):
    cfg = DynamicsConfig(iterations=1_500, eval_every=500, batch_size=64)
    logged = []
    models, res = fit_dynamics(random_y, cfg, log=lambda m, i: logged.append(i))
    assert logged == [500, 1000, 1500]
    assert res["forward_ratio"] < 0.2 and res["inverse_ratio"] < 0.5
    assert res["val_transitions"] + res["train_transitions"] == 6_000
    save_state(models, tmp_path / "dyn.pt", {"dynamics": cfg.model_dump()})
    again = load_state(DynamicsModels(19, 6, cfg.hidden), tmp_path / "dyn.pt")
    y = torch.randn(5, 19)
    a = torch.rand(5, 6) * 2 - 1
    torch.testing.assert_close(again.forward_model(y, a), models.forward_model(y, a))
    torch.testing.assert_close(again.inverse_model(y, y + 0.1), models.inverse_model(y, y + 0.1))
    # normalisation statistics travel with the weights
    torch.testing.assert_close(again.y_norm.mean, models.y_norm.mean)
    assert float(again.delta_scale.min()) >= cfg.std_floor


def test_load_models_takes_its_sizes_from_the_saved_layout(tmp_path):
    cfg = DynamicsConfig(hidden=[8])
    models = DynamicsModels(7, 4, cfg.hidden)  # a twin-like layout: 7 state, 4 action columns
    cols = {"state_columns": [f"s{i}" for i in range(7)], "action_columns": [f"a{i}" for i in range(4)]}
    save_state(models, tmp_path / "dyn.pt", {"dynamics": cfg.model_dump(), **cols})
    again = load_models(tmp_path / "dyn.pt")
    y = torch.randn(3, 7)
    torch.testing.assert_close(again.inverse_model(y, y + 0.1), models.inverse_model(y, y + 0.1))
    # no columns saved: an error naming the file, not a box push assumed
    save_state(models, tmp_path / "old.pt", {"dynamics": cfg.model_dump()})
    with pytest.raises(StageError, match=r"old\.pt.*state_columns or action_columns"):
        load_models(tmp_path / "old.pt")


def test_normalised_actions_learn_millimetre_targets_and_round_trip(tmp_path):
    # a position servo: the end moves 0.7 of its target (a few millimetres) per step, as in the twin
    rng = np.random.default_rng(0)
    n = 3_000
    y = rng.uniform(-0.05, 0.05, (n, 4)).astype(np.float32)
    a = rng.uniform(-0.008, 0.008, (n, 2)).astype(np.float32)
    y2 = y.copy()
    y2[:, :2] += 0.7 * a
    d = RandomY(y=y, a=a, y2=y2, episode=np.repeat(np.arange(n // 30), 30),
                state_columns=[f"s{i}" for i in range(4)], action_columns=["a0", "a1"])
    cfg = DynamicsConfig(hidden=[64, 64], iterations=1_500, eval_every=500, batch_size=64, action_scale="normalised")
    models, res = fit_dynamics(d, cfg)
    assert res["inverse_ratio"] < 0.02 and res["forward_ratio"] < 0.02
    torch.testing.assert_close(models.a_norm.std, torch.from_numpy(a).std(dim=0), rtol=0.05, atol=0)
    # F^-1 answers in the units the actions were recorded in
    y_n = models.y_norm(torch.from_numpy(y[:200]))
    y2_n = models.y_norm(torch.from_numpy(y2[:200]))
    with torch.no_grad():
        err = (models.inverse_model(y_n, y2_n) - torch.from_numpy(a[:200])).abs().max()
    assert float(err) < 0.002
    cols = {"state_columns": d.state_columns, "action_columns": d.action_columns}
    save_state(models, tmp_path / "dyn.pt", {"dynamics": cfg.model_dump(), **cols})
    again = load_models(tmp_path / "dyn.pt")
    torch.testing.assert_close(again.inverse_model(y_n, y2_n), models.inverse_model(y_n, y2_n))
    torch.testing.assert_close(again.forward_model(y_n, torch.from_numpy(a[:200])),
                               models.forward_model(y_n, torch.from_numpy(a[:200])))


def test_raw_actions_keep_the_state_dict_of_before():
    assert not any(k.startswith("a_norm") for k in DynamicsModels(7, 4, [8]).state_dict())
    assert {"a_norm.mean", "a_norm.std"} <= set(DynamicsModels(7, 4, [8], normalise_actions=True).state_dict())


def test_f_and_f_inverse_side_by_side_are_the_same_bits_as_one_after_the_other(random_y):
    cfg = DynamicsConfig(hidden=[32, 32], iterations=120, eval_every=40, batch_size=32)
    serial, res_s = fit_dynamics(random_y, cfg)
    parallel, res_p = fit_dynamics(random_y, cfg, workers=2)
    a, b = serial.state_dict(), parallel.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert res_s["forward_mse"] == res_p["forward_mse"] and res_s["inverse_mse"] == res_p["inverse_mse"]
    assert [c["iteration"] for c in res_p["curve"]] == [40, 80, 120]
    assert res_s["curve"][-1]["val/inverse_mse"] == res_p["curve"][-1]["val/inverse_mse"]


def test_object_frame_ratios_of_a_model_that_predicts_no_change_are_one():
    """F judged on the object in its own frame: a model whose f is 0 predicts 'nothing moves' and scores exactly 1
    in every direction; one that knows the true next state scores 0."""
    from lfdt.dynamics import object_frame_ratios
    from lfdt.tasks.box_push import columns as box_columns
    from lfdt.tasks.box_push.random_motion import push_probe

    y, a, y2 = push_probe(EnvConfig(), episodes=10, steps=40)
    m = DynamicsModels(19, 6, [8])
    torch.nn.init.zeros_(m.f.layers[-1].weight)
    torch.nn.init.zeros_(m.f.layers[-1].bias)
    r = object_frame_ratios(m, y, a, y2, box_columns.BOX_PUSH)
    assert r["transitions"] > 100
    for k in ("across", "along", "angle"):
        assert r[k] == pytest.approx(1.0, rel=1e-5)
    cols = box_columns.state_columns("Y")
    box = [cols.index(c) for c in box_columns.OBJECT_COLUMNS]
    moved = np.abs(y2[:, box] - y[:, box]).max(axis=1) > 1e-4

    class Oracle(DynamicsModels):  # knows the next state of every moving transition (its normaliser is the identity)
        def forward_model(self, y_n, a):
            return torch.as_tensor(y2[moved])

    r = object_frame_ratios(Oracle(19, 6, [8]), y, a, y2, box_columns.BOX_PUSH)
    for k in ("across", "along", "angle"):
        assert r[k] < 1e-8


def test_the_episode_split_keeps_one_episode_on_each_side_or_names_the_problem():
    train, val = split_episodes(np.repeat([0, 1, 2], 4), 0.99, seed=0)
    assert train.sum() == 4 and val.sum() == 8
    with pytest.raises(StageError, match="1 random-motion episode"):
        split_episodes(np.zeros(5, dtype=int), 0.1, seed=0)
