"""All seeding in one place.

Every episode an environment is reset for gets an integer seed from :func:`episode_seed`, built
from a *purpose* (what the episode is for), the run's seed, the domain and the episode's index.
Purposes live in disjoint blocks of 10 million integers, so evaluation start states can never
coincide with a start state used for training or data collection (``tests/test_seeding.py``).
"""

from __future__ import annotations

import random

import numpy as np

PURPOSES: dict[str, int] = {
    "expert_train": 1,
    "expert_eval": 2,
    "random": 3,
    "demos": 4,
    "translator": 5,
    "bc": 6,
    "diagnostics": 7,
    "development": 8,
    "evaluation": 9,
}
"""Purpose -> block index; the block of purpose p is [p * 10M, (p + 1) * 10M). 'development' start states are
for choosing settings during development; 'evaluation' start states are only for the reported results; 'diagnostics'
episodes probe models (e.g. F on two-arm pushes) and never train or choose anything."""

DOMAIN_INDEX: dict[str, int] = {"Y": 0, "R1H": 1, "HR2": 2}
BLOCK = 10_000_000
MAX_RUN_SEEDS = 10
MAX_EPISODES = 100_000


def episode_seed(purpose: str, run_seed: int, domain: str, episode: int) -> int:
    """The reset seed of one episode: unique for (purpose, run seed, domain, episode)."""
    if purpose not in PURPOSES:
        raise ValueError(f"unknown seed purpose {purpose!r}; expected one of {sorted(PURPOSES)}")
    if not 0 <= run_seed < MAX_RUN_SEEDS:
        raise ValueError(f"run seed {run_seed} outside [0, {MAX_RUN_SEEDS})")
    if not 0 <= episode < MAX_EPISODES:
        raise ValueError(f"episode index {episode} outside [0, {MAX_EPISODES})")
    return PURPOSES[purpose] * BLOCK + DOMAIN_INDEX[domain] * 1_000_000 + run_seed * MAX_EPISODES + episode


def seed_everything(seed: int) -> None:
    """Seed Python, NumPy and torch (training code; episode resets use :func:`episode_seed`)."""
    import torch

    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
