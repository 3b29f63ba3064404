"""The MuJoCo twin behind the rig interface, for dry runs and tests (conventions: :mod:`lfdt.robot.rig`)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from lfdt.robot.rig import Rig
from lfdt.robot.rig_config import HUMAN_DRIVERS


class SimRig(Rig):
    """The same interface over :class:`~lfdt.robot.twin.TwinEnv`, for dry runs and tests.

    In an X domain the human slot is driven by the twin's scripted person (``human="scripted"``, the human part of
    :class:`~lfdt.robot.twin.ScriptedDemo`) or by random targets held for 1..hold_max steps (``"random"``, as
    ``twin.record_random`` moves it). ``step_delay`` sleeps after each step, to pace a dry run like the robots.
    """

    def __init__(self, task: str, domain: str, seed: int = 0, human: str = "scripted", step_delay: float = 0.0,
                 max_steps: int | None = None, reach: float = 0.008, hold_max: int = 3) -> None:
        from lfdt.robot.twin import TwinConfig, TwinEnv

        self._init_slots(task, domain)
        if human not in HUMAN_DRIVERS:
            raise ValueError(f"human must be one of {HUMAN_DRIVERS}, not {human!r}")
        cfg = TwinConfig() if max_steps is None else TwinConfig(max_steps=max_steps)
        self.env = TwinEnv(task, domain, cfg)
        self.control_dt = cfg.control_dt
        self.human, self.step_delay, self.reach, self.hold_max = human, step_delay, reach, hold_max
        self._seeds = np.random.default_rng(seed)
        self._obs: np.ndarray | None = None
        self._info: dict = {}
        self._over = False
        self._human_rel = np.zeros(2)

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Reset the twin (``seed``: its start state; None: drawn from the rig's seed)."""
        from lfdt.robot.twin import ScriptedDemo

        if seed is None:
            seed = int(self._seeds.integers(2**31))
        self._obs, self._info = self.env.reset(seed=seed)
        self._over = False
        self._demo = ScriptedDemo(self.env) if self.human_slot is not None and self.human == "scripted" else None
        self._human_rng = np.random.default_rng(seed)
        self._hold = 0
        return self._obs.copy()

    def observe(self) -> np.ndarray:
        """The twin's current observation."""
        if self._obs is None:
            raise RuntimeError("reset() the rig first")
        return self._obs.copy()

    def _human_target(self, obs: np.ndarray) -> np.ndarray:
        s = self.human_slot
        if self._demo is not None:
            return self._demo(obs).reshape(2, 2)[s]
        if self._hold == 0:
            self._human_rel = self._human_rng.uniform(-self.reach, self.reach, size=2)
            self._hold = int(self._human_rng.integers(1, self.hold_max + 1))
        self._hold -= 1
        return self._human_rel

    def act(self, relative_targets: Mapping[str, Any]) -> None:
        """One twin step: the robots' relative targets, the human slot from its driver."""
        targets = self._targets(relative_targets)
        obs = self.observe()
        action = np.zeros((2, 2))
        for slot, arm in enumerate(self.slots):
            if arm == "h":
                self._human_rel = np.asarray(self._human_target(obs), dtype=float)
                action[slot] = self._human_rel
            else:
                action[slot] = targets[arm]
        self._obs, _, term, trunc, self._info = self.env.step(action.reshape(-1))
        self._over = bool(term or trunc)
        if self.step_delay > 0:
            time.sleep(self.step_delay)

    def human_action(self, obs: np.ndarray, next_obs: np.ndarray) -> np.ndarray:
        """The human slot's commanded relative target of the last step (as ``twin.record_random`` records it)."""
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
