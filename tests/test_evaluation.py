"""The interval of Table I counts both the training seeds and the start states as random draws."""

import numpy as np
import pytest

from lfdt.evaluation import seed_state_interval


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
