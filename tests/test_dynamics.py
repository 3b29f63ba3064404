"""Forward/inverse dynamics: episode-level split, learning beats the trivial predictors, saved and loaded alike."""

import numpy as np
import pytest
import torch

from lfdt import data
from lfdt.config import DynamicsConfig, EnvConfig, RandomConfig
from lfdt.dynamics import DynamicsModels, fit_dynamics, load_models, load_random_y, split_episodes
from lfdt.errors import StageError
from lfdt.nets import load_state, save_state
from lfdt.tasks.box_push.layout import BOX_PUSH
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
