"""What a task is: the small protocol every task implements (:class:`Task`), and the fuller interface of the
real-robot tasks (:class:`PlanarTask`): what the twin, the recording tools and the rig need to know.

Dynamics, translation, BC and evaluation take a task's :attr:`Task.layout` and the environments it makes; they
never import a particular task.

A real-robot task is a planar problem for two arms (slot 1: Robot1 or the person, slot 2: Robot2 or the person)
and one object. The twin (:mod:`lfdt.tasks.planar_env`) builds its MuJoCo scene from the task's parts, resets and scores
episodes through it, and the demonstrations (:mod:`lfdt.tasks.demonstrators`) ask it where the programmed robot goes and
how the scripted person adapts. Nothing outside a task's own module branches on its name.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from lfdt.layout import TaskLayout

if TYPE_CHECKING:  # the twin imports the tasks; the type is only needed for hints
    import gymnasium as gym

    from lfdt.tasks.planar_env import TwinConfig, TwinEnv

_UNIT = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


@runtime_checkable
class Task(Protocol):
    """What every task offers the code that takes a task (the registry, :mod:`lfdt.tasks.registry`, hands these out).

    The box push (:mod:`lfdt.tasks.box_push.task`) satisfies it by its shape, without importing this module; the
    real-robot tasks through :class:`PlanarTask`.
    """

    name: str
    """Registry key, also the name in params, file paths, data files' metadata and reports."""
    layout: TaskLayout
    """The task's columns: per arm its state and action columns, the object's, the ends' positions."""
    action_bounds: tuple[float, float] | None
    """The clip a policy's actions get before they reach the scene, ``(low, high)``, or None where the scene clips
    them itself."""

    def make_env(self, domain: str, config: Any = None, render_mode: str | None = None, size: int = 240) -> gym.Env:
        """A Gymnasium environment of the task in ``domain`` ('Y', 'R1H' or 'HR2'; observations in
        ``layout.state_columns(domain)`` order); ``config``: the task's environment settings (its defaults if None);
        ``render_mode`` None or 'rgb_array' of ``size`` pixels square. Every step's info holds ``'is_success'``, the
        task's success rule, and an episode terminates on it."""
        ...


class PlanarTask(Task, ABC):
    """One real-robot task: its plane, layout, scene, start states, success rule and demonstrators.

    Subclasses set the class attributes and implement the abstract methods; the module exposes an instance as
    ``TASK``, registered in :data:`lfdt.tasks.registry.TASKS`.
    """

    name: str
    """Registry key, also the name in params, file paths and reports."""
    plane: tuple[str, str]
    """The world axes of the task plane, e.g. ('x', 'y'): the state's 2 numbers per arm."""
    angle: str
    """Name of the object's in-plane angle (a state column 'obj.<angle>')."""
    angle_axis: str
    """The world axis ('x', 'y' or 'z') the object's angle turns about, positive by the right-hand rule."""
    workspace: np.ndarray
    """[[low a, low b], [high a, high b]] of the task plane, m: every commanded target is clipped into it."""
    action_bounds = None
    """Actions are targets on the plane: the scene clips them into :attr:`workspace`, the policy does not."""

    # ------------------------------------------------------------------ derived geometry
    @property
    def axes(self) -> tuple[int, int]:
        """Indices of the plane's axes in a 3D world vector."""
        return ("xyz".index(self.plane[0]), "xyz".index(self.plane[1]))

    @property
    def normal(self) -> tuple[float, float, float]:
        """Unit vector of the axis the object's angle turns about (normal to the plane)."""
        return _UNIT[self.angle_axis]

    @property
    def layout(self) -> TaskLayout:
        """The column layout: 2 numbers per arm (its end in the plane), their relative targets, the object's pose."""
        a, b = self.plane
        arms = ("r1", "r2", "h")
        pos = {arm: [f"{arm}.{a}", f"{arm}.{b}"] for arm in arms}
        return TaskLayout(self.name, pos, {arm: [f"{arm}.d{a}", f"{arm}.d{b}"] for arm in arms},
                          [f"obj.{a}", f"obj.{b}", f"obj.{self.angle}"], pos)

    def make_env(self, domain: str, config: TwinConfig | None = None, render_mode: str | None = None,
                 size: int = 240) -> TwinEnv:
        """The task in the MuJoCo twin (:class:`lfdt.tasks.planar_env.TwinEnv`); ``config``: the twin's settings."""
        from lfdt.tasks.planar_env import TwinEnv

        return TwinEnv(self.name, domain, config, render_mode, size)

    def plane_angle(self, quat: np.ndarray) -> float:
        """In-plane angle (rad, wrapped to [-pi, pi)) of a body's orientation quaternion (w, x, y, z)."""
        angle = 2 * math.atan2(quat[1 + "xyz".index(self.angle_axis)], quat[0])
        return (angle + math.pi) % (2 * math.pi) - math.pi

    # ------------------------------------------------------------------ the scene
    def arm_geom(self, slot: int, colour: str) -> str:
        """MJCF of a robot's end effector (a body's contents), in slot 1 or 2."""
        return f'<geom type="box" size="0.012 0.012 0.012" rgba="{colour}" mass="0.2"/>'

    def held_part(self, slot: int, human: bool) -> str:
        """MJCF a slot's end effector or hand carries rigidly (none by default)."""
        return ""

    @abstractmethod
    def object_xml(self, arms: tuple[str, str]) -> str:
        """MJCF of the object body, named 'obj'."""

    def extra_xml(self) -> str:
        """Decoration of the world body (markers without contact)."""
        return ""

    @abstractmethod
    def camera_xml(self) -> str:
        """MJCF of the camera named 'view' that renders the task plane."""

    def equality_xml(self, arms: tuple[str, str]) -> str:
        """MJCF equality constraints of the task (grasps), besides the hand's weld."""
        return ""

    # ------------------------------------------------------------------ episodes
    @abstractmethod
    def reset(self, env: TwinEnv, rng: np.random.Generator) -> list[np.ndarray]:
        """Place the object for a new episode and return each slot's start end position (plane, m)."""

    def random_motion_start(self, env: TwinEnv, rng: np.random.Generator) -> list[np.ndarray]:
        """Like :meth:`reset`, for an episode of random motion (the task's start state by default; a task whose
        demonstrations travel far from it starts its random motion along the way, so that F and F^-1 see those
        states too)."""
        return self.reset(env, rng)

    def settle(self, env: TwinEnv) -> None:  # noqa: B027 (optional hook: most tasks need nothing)
        """Let the scene settle after a reset (nothing by default)."""

    @abstractmethod
    def info(self, env: TwinEnv) -> dict[str, Any]:
        """The step's info: 'is_success' and the task's own measures."""

    # ------------------------------------------------------------------ demonstrations
    @abstractmethod
    def program_waypoint(self, robot_slot: int, start: np.ndarray, obs: np.ndarray,
                         goal_line: float | None = None) -> np.ndarray:
        """Where the programmed robot of ``robot_slot`` moves its end from ``start`` (set once per take from the
        first observation ``obs``; ``goal_line``: the real rig's configured goal, where the task has one)."""

    @abstractmethod
    def person_target(self, env: TwinEnv, human_slot: int, robot_slot: int, obs: np.ndarray) -> np.ndarray:
        """The scripted person's next absolute hand target (plane, m), adapting to the robot and the object."""

    # ------------------------------------------------------------------ the real rig
    @abstractmethod
    def example_rig(self) -> tuple[dict, dict, dict, dict]:
        """An example real setup with the world frame placed like the twin's: Robot1's and Robot2's arm entries,
        the table tag's pose and task-specific top-level keys (see :func:`lfdt.robot.rig_config.example_rig_config`)."""
