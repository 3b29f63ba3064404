"""The rig interface: the whole real setup behind one interface, two myCobot 280 arms and a camera
(:class:`~lfdt.robot.real_rig.RealRig`), or the MuJoCo twin standing in for it
(:class:`~lfdt.rig.sim.SimRig`), both speaking the twin's observation and action conventions. Their
configuration is :mod:`lfdt.robot.rig_config`.

**World frame.** One table frame shared by both arms and the camera, in millimetres in the configuration and metres
in observations, like the twin's: block push moves in the horizontal plane (x, y), peg insertion in the vertical
plane (x, z). Each arm's base pose in that frame comes from :class:`~lfdt.robot.rig_config.RigConfig`; the camera's
comes from the table tag, whose pose in the world frame is configured (so :class:`~lfdt.robot.tracker.Tracker`
reports in the world frame directly). To replay :class:`~lfdt.tasks.demonstrators.ProgrammedMotion` unchanged, put the
world frame where the twin's is (see :func:`~lfdt.robot.rig_config.example_rig_config`).

**State** (layout ``registry.get(task).layout.state_columns(domain)``, metres and radians): per slot the end position in
the task plane (a robot's flange from forward kinematics of its joint angles, moved to the world frame; the hand's
tag centre from the tracker), then the object tag's position in the plane and its angle in the plane: the twist of
the tag's rotation about the plane's normal (block push: yaw about world +z; peg insertion: pitch about world +y,
the twin's sign), minus ``camera.object_angle_offset_deg`` (the tag's mounting angle on the object).

**Action**: per robot, the target end position relative to the end position of the last observation (metres, in the
task plane), as in the twin. :meth:`~lfdt.robot.real_rig.RealRig.act` puts the target on the arm's task plane, moves
it into the arm's base frame, keeps it inside the arm's workspace (the task plane's bounds intersected with the
arm's safety box: clipped, as the twin clips its targets, or refused with ``clip_to_workspace: false``), solves our
IK seeded with the current angles and sends the joint angles through :class:`~lfdt.robot.arm.SafeArm`. All robots'
commands are validated before any is sent, so a refusal reaches no arm.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import numpy as np

from lfdt import layout
from lfdt.rig.interrupt import stop_on_interrupt
from lfdt.tasks import registry

HUMAN_DRIVERS = ("scripted", "random")
"""How a rig's human slot moves: the twin's scripted person, or random motion the caller draws (the real rig: the
person's own hand)."""


def plane_angle(rotation: np.ndarray, task: str) -> float:
    """In-plane angle (rad) of a rotation: its twist about the axis the task's object angle turns about."""
    from lfdt.poses import rotation_about_axis

    return rotation_about_axis(rotation, registry.get(task).normal)


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


class Rig(ABC):
    """Observe the state of a domain and command its robots, in the twin's conventions (see the module doc)."""

    task: str
    domain: str
    control_dt: float

    def _init_slots(self, task: str, domain: str) -> None:
        task_def = registry.get(task)
        if domain not in layout.DOMAINS:
            raise ValueError(f"unknown domain {domain!r}; expected one of {layout.DOMAINS}")
        self.task, self.domain = task, domain
        self.layout = task_def.layout
        self.slots: tuple[str, str] = layout.DOMAIN_ARMS[domain]
        self.robots: tuple[str, ...] = tuple(a for a in self.slots if a != "h")
        self.human_slot: int | None = self.slots.index("h") if "h" in self.slots else None

    def state_columns(self) -> list[str]:
        """Names of the observation's entries."""
        return self.layout.state_columns(self.domain)

    def _targets(self, relative_targets: Mapping[str, Any]) -> dict[str, np.ndarray]:
        if set(relative_targets) != set(self.robots):
            raise ValueError(f"domain {self.domain} commands {list(self.robots)}, got {sorted(relative_targets)}")
        out = {}
        for arm, rel in relative_targets.items():
            v = np.asarray(rel, dtype=float).reshape(-1)
            if v.shape != (2,):
                raise ValueError(f"{arm}: a relative target has 2 numbers (m, in the task plane), got {v.shape}")
            out[arm] = v
        return out

    @abstractmethod
    def observe(self) -> np.ndarray:
        """The state (``state_columns()`` order), metres and radians in the world frame's task plane."""

    @abstractmethod
    def act(self, relative_targets: Mapping[str, Any], human_target: Any = None) -> None:
        """Command each robot of the domain to its end's target relative to the last observation (m, 2 numbers).

        ``human_target``: where a recording would like the person's hand to go (relative, m); a simulated person
        may follow it, a real one moves as they do."""

    @abstractmethod
    def reset(self, seed: int | None = None) -> np.ndarray:
        """Bring the rig to a start state and return the first observation."""

    def human_action(self, obs: np.ndarray, next_obs: np.ndarray) -> np.ndarray:
        """What is recorded as the human slot's action: its relative target (sim) or its measured motion (real)."""
        s = self.human_slot
        if s is None:
            raise ValueError(f"domain {self.domain} has no human")
        return np.asarray(next_obs[2 * s:2 * s + 2] - obs[2 * s:2 * s + 2], dtype=float)

    def outcome(self) -> bool | None:
        """Whether the task succeeded, if the rig can tell (the twin can; the real rig asks the operator)."""
        return None

    @property
    def done(self) -> bool:
        """The episode is over by the rig's own rule (the twin's success or time limit); never on the robots."""
        return False

    @abstractmethod
    def stop(self) -> None:
        """Stop every arm (Ctrl-C, errors)."""

    @abstractmethod
    def close(self) -> None:
        """Release everything; safe to call twice."""

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@contextmanager
def running(rig: Rig) -> Iterator[Rig]:
    """Within the block: Ctrl-C stops and closes the rig, then KeyboardInterrupt propagates; any other error stops
    the arms before it propagates; the rig is closed on the way out in every case."""
    try:
        with stop_on_interrupt(rig):
            try:
                yield rig
            except Exception:
                rig.stop()  # stop first: close alone would leave the arms moving to their last target
                raise
    finally:
        rig.close()
