"""Seeds of different purposes never coincide: evaluation start states are disjoint from training's."""

import pytest

from lfdt.seeding import DOMAIN_INDEX, MAX_EPISODES, MAX_RUN_SEEDS, PURPOSES, episode_seed


def test_purpose_blocks_are_disjoint():
    ranges = {}
    for p in PURPOSES:
        seeds = [episode_seed(p, s, d, e) for s in (0, MAX_RUN_SEEDS - 1) for d in DOMAIN_INDEX
                 for e in (0, MAX_EPISODES - 1)]
        ranges[p] = (min(seeds), max(seeds))
    items = sorted(ranges.values())
    for (_, hi1), (lo2, _) in zip(items, items[1:]):
        assert hi1 < lo2


def test_unique_within_purpose():
    seen = {episode_seed("demos", s, d, e) for s in range(3) for d in DOMAIN_INDEX for e in range(0, MAX_EPISODES, 997)}
    assert len(seen) == 3 * len(DOMAIN_INDEX) * len(range(0, MAX_EPISODES, 997))


def test_out_of_range_is_refused():
    with pytest.raises(ValueError, match="episode index"):
        episode_seed("demos", 0, "Y", MAX_EPISODES)
    with pytest.raises(ValueError, match="run seed"):
        episode_seed("demos", MAX_RUN_SEEDS, "Y", 0)
    with pytest.raises(ValueError, match="purpose"):
        episode_seed("lucky", 0, "Y", 0)
