"""The MuJoCo twin behind the rig interface, for dry runs and tests (conventions: :mod:`lfdt.rig.base`)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from lfdt.rig.base import HUMAN_DRIVERS, Rig


class SimRig(Rig):
    """The same interface over :class:`~lfdt.tasks.planar_env.TwinEnv`, for dry runs and tests.

    In an X domain the human slot is driven by the twin's scripted person (``human="scripted"``, the person of
    :class:`~lfdt.tasks.demonstrators.TwinDemonstrator`) or moves to the relative target the caller offers with each
    step (``"random"``: :func:`lfdt.rig.recording.record_random_episode` draws it). ``step_delay`` sleeps after
    each step, to pace a dry run like the robots.
    """

    def __init__(self, task: str, domain: str, seed: int = 0, human: str = "scripted", step_delay: float = 0.0,
                 max_steps: int | None = None) -> None:
        from lfdt.tasks.planar_env import TwinConfig, TwinEnv

        self._init_slots(task, domain)
        if human not in HUMAN_DRIVERS:
            raise ValueError(f"human must be one of {HUMAN_DRIVERS}, not {human!r}")
        cfg = TwinConfig() if max_steps is None else TwinConfig(max_steps=max_steps)
        self.env = TwinEnv(task, domain, cfg)
        self.control_dt = cfg.control_dt
        self.human, self.step_delay = human, step_delay
        self._seeds = np.random.default_rng(seed)
        self._obs: np.ndarray | None = None
        self._info: dict = {}
        self._over = False
        self._human_rel = np.zeros(2)

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Reset the twin (``seed``: its start state; None: drawn from the rig's seed)."""
        from lfdt.tasks.demonstrators import TwinDemonstrator

        if seed is None:
            seed = int(self._seeds.integers(2**31))
        # the random person ("random") records random motion, which starts where the task says it should
        self._obs, self._info = self.env.reset(seed=seed, options={"random_motion": self.human == "random"})
        self._over = False
        self._demo = TwinDemonstrator(self.env) if self.human_slot is not None and self.human == "scripted" else None
        return self._obs.copy()

    def observe(self) -> np.ndarray:
        """The twin's current observation."""
        if self._obs is None:
            raise RuntimeError("reset() the rig first")
        return self._obs.copy()

    def act(self, relative_targets: Mapping[str, Any], human_target: Any = None) -> None:
        """One twin step: the robots' relative targets; the human slot from the scripted person, or (``"random"``)
        to ``human_target``, its target relative to the hand (m, 2 numbers)."""
        targets = self._targets(relative_targets)
        obs = self.observe()
        action = np.zeros((2, 2))
        for slot, arm in enumerate(self.slots):
            if arm == "h":
                if self._demo is not None:
                    rel = self._demo(obs).reshape(2, 2)[slot]
                elif human_target is None:
                    raise ValueError("SimRig(human='random') moves the person to the human_target act() is given; "
                                     "none was")
                else:
                    rel = np.asarray(human_target, dtype=float).reshape(2)
                self._human_rel = np.asarray(rel, dtype=float)
                action[slot] = self._human_rel
            else:
                action[slot] = targets[arm]
        self._obs, _, term, trunc, self._info = self.env.step(action.reshape(-1))
        self._over = bool(term or trunc)
        if self.step_delay > 0:
            time.sleep(self.step_delay)

    def human_action(self, obs: np.ndarray, next_obs: np.ndarray) -> np.ndarray:
        """The human slot's commanded relative target of the last step."""
        if self.human_slot is None:
            raise ValueError(f"domain {self.domain} has no human")
        return self._human_rel.copy()

    def outcome(self) -> bool | None:
        """The twin's success flag after the last step."""
        return bool(self._info.get("is_success", False))

    @property
    def done(self) -> bool:
        """Success or the twin's step limit."""
        return self._over

    def stop(self) -> None:
        """Nothing moves on its own in the twin."""

    def close(self) -> None:
        """Close the twin."""
        self.env.close()
