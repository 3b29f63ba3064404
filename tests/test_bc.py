import lfdt.numerics  # noqa: F401

import numpy as np
import pandas as pd
import pytest
import torch

from lfdt import bc
from lfdt.config import BCConfig


def frame(seed: int, episodes: int = 12, steps: int = 15) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    n = episodes * steps
    s = rng.normal(size=(n, 5)).astype(np.float32)
    a = np.tanh(s[:, :2] @ rng.normal(size=(2, 2))).astype(np.float32)
    df = pd.DataFrame(s, columns=[f"state.c{i}" for i in range(5)])
    df[["action.a0", "action.a1"]] = a
    df.insert(0, "episode_index", np.repeat(np.arange(episodes), steps))
    return df


def task(seed: int) -> bc.BCTask:
    return bc.BCTask("pi", [f"c{i}" for i in range(5)], ["a0", "a1"], frame(seed))


@pytest.mark.parametrize("noise", [0.0, 0.1])
def test_a_seed_clones_to_the_same_bits_alone_and_in_a_stack(noise):
    """BC policies of several seeds train as one stack; each is the same bits as its seed trained alone (own data,
    split, initialisation, minibatches, input noise, kept checkpoint)."""
    cfg = BCConfig(hidden=[32, 32], iterations=120, eval_every=40, batch_size=16, input_noise=noise)
    seeds = [3, 8, 13]
    tasks = [task(s) for s in seeds]
    stacked, st_stats = bc.train_members(tasks, cfg, seeds)
    for k, seed in enumerate(seeds):
        alone, stats = bc.train_member(tasks[k], cfg, seed)
        a, b = alone.state_dict(), stacked[k].state_dict()
        assert all(torch.equal(a[key], b[key]) for key in a), f"seed {seed}: other bits in a stack"
        assert stats["curve"] == st_stats[k]["curve"] and stats["best_iteration"] == st_stats[k]["best_iteration"]
    assert not torch.equal(stacked[0].net.layers[0].weight, stacked[1].net.layers[0].weight)
    assert st_stats[0]["curve"][-1]["pi/val_loss"] < st_stats[0]["curve"][0]["pi/val_loss"] * 1.5


def test_members_of_other_columns_do_not_stack():
    other = bc.BCTask("pi_r1", ["c0"], ["a0"], frame(1))
    with pytest.raises(ValueError, match="same columns"):
        bc.train_members([task(0), other], BCConfig(iterations=2), [0, 1])


def test_recovery_copies_are_perturbed_states_labelled_back_onto_the_demonstration():
    from lfdt import layout
    from lfdt.dynamics import DynamicsModels
    from lfdt.tasks.box_push import columns as box_columns

    tl = box_columns.BOX_PUSH
    s_cols, a_cols = tl.state_columns("Y"), tl.action_columns("Y")
    rng = np.random.default_rng(0)
    n = 40
    df = pd.DataFrame(rng.normal(size=(n, len(s_cols))).astype(np.float32),
                      columns=[layout.STATE_PREFIX + c for c in s_cols])
    df[[layout.NEXT_STATE_PREFIX + c for c in s_cols]] = df[[layout.STATE_PREFIX + c for c in s_cols]].to_numpy() + 0.1
    df[[layout.ACTION_PREFIX + c for c in a_cols]] = 0.5
    df["episode_index"] = np.arange(n) // 10
    torch.manual_seed(0)
    dyn = DynamicsModels(len(s_cols), len(a_cols), [16])
    assert bc.recovery_augment(df, dyn, tl, 0, 0.1, 3) is df
    out = bc.recovery_augment(df, dyn, tl, 2, 0.1, 3)
    assert len(out) == 3 * n and (out.episode_index.to_numpy() == np.tile(df.episode_index, 3)).all()
    copy = out.iloc[n:2 * n]
    s = copy[[layout.STATE_PREFIX + c for c in s_cols]].to_numpy(np.float32)
    assert not np.allclose(s, df[[layout.STATE_PREFIX + c for c in s_cols]].to_numpy())  # perturbed
    with torch.no_grad():
        y_n = dyn.y_norm(torch.from_numpy(s))
        y2_n = dyn.y_norm(torch.from_numpy(copy[[layout.NEXT_STATE_PREFIX + c for c in s_cols]].to_numpy(np.float32)))
        want = torch.clamp(dyn.inverse_model(y_n, y2_n), -1, 1).numpy()
    np.testing.assert_allclose(copy[[layout.ACTION_PREFIX + c for c in a_cols]].to_numpy(), want, atol=1e-5)
    assert out.equals(bc.recovery_augment(df, dyn, tl, 2, 0.1, 3))  # the seed fixes the perturbations


def test_a_high_validation_fraction_of_few_episodes_leaves_one_to_train_on():
    """bc.val_fraction 0.9 of two episodes (a cell whose re-executions mostly failed) keeps one for training; the
    split of many episodes is what it always was."""
    from lfdt.bc import _split

    val = _split(np.repeat([0, 1], 5), 0.9, np.random.default_rng(0))
    assert val.sum() == 5 and (~val).sum() == 5
    many = np.repeat(np.arange(40), 3)
    assert _split(many, 0.1, np.random.default_rng(0)).sum() == 4 * 3
