"""Restarts: several translators of one configuration (same data, other initialisations), their seeds and metric
names, trained as one stack."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from lfdt.config import TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.translation.model import Translator
from lfdt.translation.training import Member, train_translators
from lfdt.translation.transitions import Transitions

RESTART_SEED_STRIDE = 1000
"""Restart r of a translator of seed s trains with seed s + RESTART_SEED_STRIDE * r (r = 0: the translator itself)."""


def restart_seed(seed: int, r: int) -> int:
    """The initialisation seed of restart ``r`` of a translator of seed ``seed``."""
    return seed + RESTART_SEED_STRIDE * r


def restart_key(r: int, key: str) -> str:
    """The name of restart ``r``'s metric ``key``: restart 0 under the plain name, restart r > 0 under
    ``restart<r>/``."""
    return key if r == 0 else f"restart{r}/{key}"


def restart_log(log: Callable[[dict, int], None] | None, r: int) -> Callable[[dict, int], None] | None:
    """``log`` with restart r's metric names (:func:`restart_key`)."""
    if log is None or r == 0:
        return log
    return lambda m, i: log({restart_key(r, k): v for k, v in m.items()}, i)


def train_restarts(demos: dict[str, Transitions], random_x: dict[str, Transitions], y_random: np.ndarray,
                   dyn: DynamicsModels, cfg: TranslatorConfig, seed: int,
                   log: Callable[[dict, int], None] | None = None, held_out: dict[str, Transitions] | None = None,
                   **kwargs) -> tuple[list[Translator], list[dict]]:
    """``cfg.restarts`` translators of one configuration (seeds seed + 1000 r), trained as one stack. Restart 0 logs
    under its own names, restart r > 0 under ``restart<r>/``."""
    members = [Member(demos, restart_seed(seed, r), held_out) for r in range(cfg.restarts)]
    return train_translators(members, random_x, y_random, dyn, cfg,
                             logs=[restart_log(log, r) for r in range(cfg.restarts)], **kwargs)
