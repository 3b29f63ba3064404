"""The interval of Table I counts both the training seeds and the start states as random draws; the paired difference
of two methods pairs their seeds and start states; a group's lockstep evaluation is each seed's own."""

import lfdt.numerics  # noqa: F401

import numpy as np
import pytest

from lfdt.evaluation import paired_difference_interval, seed_state_interval


def _draw(rng, seeds, states, mean=0.7, sd_seed=0.15, sd_state=1.0):
    """A crossed design: success probability from a seed effect and a start-state effect (logit scale)."""
    logit = np.log(mean / (1 - mean)) + rng.normal(0, sd_seed * 4, (seeds, 1)) + rng.normal(0, sd_state, (1, states))
    return (rng.random((seeds, states)) < 1 / (1 + np.exp(-logit))).astype(float)


def test_interval_contains_the_mean_and_narrows_with_more_seeds():
    rng = np.random.default_rng(0)
    y3 = _draw(rng, 3, 200)
    lo, hi = seed_state_interval(y3)
    assert lo <= y3.mean() <= hi
    widths = []
    for seeds in (3, 10, 30):
        widths.append(np.mean([np.diff(seed_state_interval(_draw(rng, seeds, 200)))[0] for _ in range(20)]))
    assert widths[0] > widths[1] > widths[2]


def test_seed_differences_widen_the_interval():
    same = np.tile(np.r_[np.ones(140), np.zeros(60)], (3, 1))  # every seed solves the same 140 of 200 states
    apart = np.array([np.r_[np.ones(n), np.zeros(200 - n)] for n in (100, 140, 180)])
    assert same.mean() == pytest.approx(apart.mean())
    assert np.diff(seed_state_interval(apart))[0] > 2 * np.diff(seed_state_interval(same))[0]


def test_coverage_of_the_true_mean():
    """Over repeated crossed experiments the 95 % interval covers the true mean success rate most of the time
    (the true mean of the generating model, estimated from a very large draw)."""
    rng = np.random.default_rng(1)
    truth = _draw(np.random.default_rng(2), 2000, 2000).mean()
    covered = 0
    n = 200
    for _ in range(n):
        lo, hi = seed_state_interval(_draw(rng, 3, 200))
        covered += lo <= truth <= hi
    assert covered / n >= 0.85


def test_shapes():
    assert seed_state_interval(np.ones((1, 10))) == (1.0, 1.0)
    lo, hi = seed_state_interval(np.array([[1, 0, 1, 0, 1.0]]))
    assert 0 <= lo < 0.6 < hi <= 1
    with pytest.raises(ValueError):
        seed_state_interval(np.ones(5))


def test_pairing_narrows_the_difference_of_two_methods_that_share_their_hard_states():
    """Two methods with the same hard start states and seed effects: the paired interval of their difference is far
    narrower than an interval that ignores the pairing would be, and it excludes 0 when one is better."""
    rng = np.random.default_rng(3)
    seeds, states = 10, 200
    hard = rng.normal(0, 1.5, (1, states))
    seed_fx = rng.normal(0, 0.6, (seeds, 1))
    u = rng.random((seeds, states))
    a = (u < 1 / (1 + np.exp(-(1.5 + hard + seed_fx)))).astype(float)
    b = (u < 1 / (1 + np.exp(-(0.8 + hard + seed_fx)))).astype(float)
    lo, hi = paired_difference_interval(a, b)
    assert 0 < lo <= (a - b).mean() <= hi
    width_unpaired = np.diff(seed_state_interval(a))[0] + np.diff(seed_state_interval(b))[0]
    assert hi - lo < 0.5 * width_unpaired
    lo0, hi0 = paired_difference_interval(a, a)
    assert lo0 == hi0 == 0.0
    with pytest.raises(ValueError, match="same seeds and start states"):
        paired_difference_interval(a, b[:, :100])


@pytest.mark.slow
def test_a_seed_is_evaluated_the_same_alone_and_in_its_group():
    """Lockstep evaluation: a policy's trials (and so its success) do not depend on the other policies of its group
    nor on which trials are still running."""
    import pandas as pd

    from lfdt import bc, layout
    from lfdt.box_push_jobs.evaluate import box_push_trials
    from lfdt.config import BCConfig, EnvConfig
    from lfdt.tasks.box_push import columns as box_columns

    tl = box_columns.BOX_PUSH
    cols, acts = tl.state_columns("Y"), tl.action_columns("Y")
    rng = np.random.default_rng(0)
    tasks = []
    for _ in range(3):
        df = pd.DataFrame(rng.normal(size=(200, len(cols))).astype(np.float32),
                          columns=[layout.STATE_PREFIX + c for c in cols])
        df[[layout.ACTION_PREFIX + c for c in acts]] = rng.uniform(-1, 1, (200, len(acts))).astype(np.float32)
        df["episode_index"] = np.arange(200) // 20
        tasks.append(bc.tasks_for("lfdt", translated=df, tl=tl)[0])
    members, _ = bc.train_members(tasks, BCConfig(hidden=[16], iterations=20, eval_every=10), [0, 1, 2])
    policies = [bc.BCPolicy([m], tl) for m in members]
    group = box_push_trials(bc.StackedPolicies(policies), 3, EnvConfig(), 4, purpose="development")
    for k, pol in enumerate(policies):
        alone = box_push_trials(bc.StackedPolicies([pol]), 1, EnvConfig(), 4, purpose="development")[0]
        assert alone == group[k]
    assert group[0] != group[1]  # the policies differ, so would their trials
