"""The whole real setup behind one interface: two myCobot 280 arms and a camera (:class:`RealRig`), or the MuJoCo
twin standing in for it (:class:`SimRig`), both speaking the twin's observation and action conventions.

**World frame.** One table frame shared by both arms and the camera, in millimetres in the configuration and metres
in observations, like the twin's: block push moves in the horizontal plane (x, y), peg insertion in the vertical
plane (x, z). Each arm's base pose in that frame comes from :class:`RigConfig`; the camera's comes from the table
tag, whose pose in the world frame is configured (so :class:`~lfdt.robot.tracker.Tracker` reports in the world
frame directly). To replay :class:`~lfdt.robot.twin.ProgrammedMotion` unchanged, put the world frame where the
twin's is (see :func:`example_rig_config`).

**State** (layout ``twin.LAYOUTS[task].state_columns(domain)``, metres and radians): per slot the end position in
the task plane (a robot's flange from forward kinematics of its joint angles, moved to the world frame; the hand's
tag centre from the tracker), then the object tag's position in the plane and its angle in the plane: the twist of
the tag's rotation about the plane's normal (block push: yaw about world +z; peg insertion: pitch about world +y,
the twin's sign), minus ``camera.object_angle_offset_deg`` (the tag's mounting angle on the object).

**Action**: per robot, the target end position relative to the end position of the last observation (metres, in
the task plane), as in the twin. :meth:`RealRig.act` puts the target on the arm's task plane, moves it into the
arm's base frame, keeps it inside the arm's workspace (the task plane's bounds intersected with the arm's safety
box: clipped, as the twin clips its targets, or refused with ``clip_to_workspace: false``), solves our IK seeded
with the current angles and sends the joint angles through :class:`~lfdt.robot.arm.SafeArm`. All robots' commands
are validated before any is sent, so a refusal reaches no arm.
"""

from __future__ import annotations

import json
import math
import os
import time
from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from lfdt import layout
from lfdt.robot import kinematics
from lfdt.robot.arm import SafeArm, SafetyError, SafetyLimits, TrackingLost, check_command, stop_on_interrupt
from lfdt.robot.twin import LAYOUTS, TASKS

HUMAN_DRIVERS = ("scripted", "random")


class RigConfigError(ValueError):
    """A rig configuration file that cannot be used; the message names the file and the key."""


# ---------------------------------------------------------------------------------------------------------------
# configuration


class _Model(BaseModel):
    # strict: a quoted number or a list where an object belongs is an error, not silently converted
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, use_attribute_docstrings=True,
                              populate_by_name=True)


def rotation_rpy(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (fixed-axis roll-pitch-yaw, as myCobot reports its flange)."""
    r, p, y = np.radians([roll_deg, pitch_deg, yaw_deg])
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


class Pose(_Model):
    """A rigid pose in the world (table) frame: position in mm, orientation ``Rz(yaw) Ry(pitch) Rx(roll)`` in deg."""

    x_mm: float = 0.0
    y_mm: float = 0.0
    z_mm: float = 0.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0

    def matrix(self, scale: float = 1.0) -> np.ndarray:
        """``world_from_frame`` (4x4); ``scale`` converts the translation (1e-3 for metres)."""
        t = np.eye(4)
        t[:3, :3] = rotation_rpy(self.roll_deg, self.pitch_deg, self.yaw_deg)
        t[:3, 3] = np.array([self.x_mm, self.y_mm, self.z_mm]) * scale
        return t


Vec3 = tuple[float, float, float]


class MyCobotConfig(_Model):
    """One myCobot 280: where it is connected, where its base stands, and what the safety layer allows."""

    port: str | None = None
    """Serial port (e.g. /dev/ttyUSB0); give exactly one of port and host."""
    host: str | None = None
    """IP address of the arm's TCP server (myCobot 280 Pi / JN)."""
    netport: Annotated[int, Field(ge=1, le=65535)] = 9000
    """TCP port of the arm's server."""
    baudrate: Annotated[int, Field(gt=0)] = 115200
    """Serial baud rate."""
    connect_timeout_s: Annotated[float, Field(gt=0)] = 3.0
    """Seconds to wait for the TCP connection."""
    base: Pose
    """The arm's base frame in the world frame (measure it; the base frame is the one of our kinematics)."""
    speed: Annotated[int, Field(ge=1, le=100)] = 30
    """send_angles speed, 1..100."""
    max_step_deg: Annotated[float, Field(gt=0)] = 15.0
    """Largest change of any joint in one command (catches IK branch flips)."""
    workspace_min_mm: Vec3 | None = None
    """Smallest flange x, y, z in the arm's base frame; None: the task plane's bounds less 10 mm."""
    workspace_max_mm: Vec3 | None = None
    """Largest flange x, y, z in the arm's base frame; None: the task plane's bounds plus 10 mm."""
    start_angles_deg: tuple[float, float, float, float, float, float] | None = None
    """Where reset() brings the arm (degrees); None: kinematics.home_angles(task)."""

    @model_validator(mode="after")
    def _one_connection(self) -> MyCobotConfig:
        if (self.port is None) == (self.host is None):
            raise ValueError("give exactly one of 'port' (serial) or 'host' (TCP)")
        return self


class CameraConfig(_Model):
    """The camera and the AprilTags it tracks."""

    source: int | str
    """Camera index (V4L2 on Linux) or a video file path (relative paths: from the config file's folder)."""
    calibration: str
    """Camera calibration JSON (`python -m lfdt.robot calibrate`); relative paths: from the config file's folder."""
    table_tag_id: Annotated[int, Field(ge=0)] = 0
    """Id of the AprilTag fixed on the table (gives the camera's pose)."""
    table_tag_pose: Pose
    """Pose of the table tag in the world frame (tag frame: x right of the print, y up, z out of the face)."""
    table_tag_size_m: Annotated[float, Field(gt=0)] | None = None
    """Edge of the table tag's black square, m; None: tag_size_m."""
    hand_tag_id: Annotated[int, Field(ge=0)] = 1
    """Id of the tag worn on the demonstrator's hand."""
    object_tag_id: Annotated[int, Field(ge=0)] = 2
    """Id of the tag on the object."""
    tag_size_m: Annotated[float, Field(gt=0)] = 0.065
    """Edge of the hand and object tags' black squares, m."""
    object_angle_offset_deg: float = 0.0
    """The object tag's angle in the task plane when the object is at angle 0 (its mounting angle), degrees."""

    @model_validator(mode="after")
    def _distinct_tags(self) -> CameraConfig:
        if len({self.table_tag_id, self.hand_tag_id, self.object_tag_id}) != 3:
            raise ValueError("table_tag_id, hand_tag_id and object_tag_id must differ")
        return self


class RigConfig(_Model):
    """The real setup of one task: both arms, the camera, the control loop. Load with :func:`load_rig_config`."""

    notes: dict[str, str] = Field(default_factory=dict, alias="_notes")
    """Free-form explanations (ignored)."""
    task: Literal["block_push", "peg_insertion"]
    """The real task (its plane and tool orientation: kinematics.TASK_PLANES)."""
    control_period_s: Annotated[float, Field(gt=0)] = 0.1
    """Time from one command to the next observation (the twin's control_dt)."""
    max_lost_frames: Annotated[int, Field(ge=0)] = 5
    """Consecutive camera frames without the needed tags tolerated before the arms are stopped."""
    max_relative_target_mm: Annotated[float, Field(gt=0)] = 40.0
    """A relative target longer than this is refused (a policy gone wrong), mm."""
    clip_to_workspace: bool = True
    """Targets outside an arm's workspace are clipped onto it (as the twin does); false: refused."""
    goal_line_m: float | None = None
    """block_push: world y of the line the block is pushed onto, for record-demos; None: the twin's 0.22 m."""
    reset_settle_s: Annotated[float, Field(ge=0)] = 5.0
    """reset(): longest wait for the arms to reach their start angles, s."""
    arms: dict[Literal["r1", "r2"], MyCobotConfig] = Field(min_length=1)
    """The arms present, by name (r1: Robot1 in slot 1, r2: Robot2 in slot 2)."""
    camera: CameraConfig
    """The camera and its tags."""

    @model_validator(mode="after")
    def _geometry(self) -> RigConfig:
        plane = kinematics.TASK_PLANES[self.task]
        f = plane.fixed_axis
        for name, arm in self.arms.items():
            r = arm.base.matrix()[:3, :3]
            # the arm's task plane must cross the world's task plane at a usable angle to project targets onto it
            if abs(r[f, f]) < 0.5:
                raise ValueError(f"arms.{name}.base: the arm's {self.task} plane is more than 60 deg from the "
                                 f"world's; check yaw_deg/roll_deg/pitch_deg")
            try:
                workspace_bounds(self.task, arm)
            except ValueError as e:
                raise ValueError(f"arms.{name}: {e}") from None
        return self


def workspace_bounds(task: str, arm: MyCobotConfig) -> tuple[np.ndarray, np.ndarray]:
    """The arm's 2D workspace in its base frame (free coordinates of the task plane, mm): the plane's bounds
    intersected with the safety box. Raises ValueError when they do not overlap or the plane misses the box."""
    plane = kinematics.TASK_PLANES[task]
    lo_box, hi_box = safety_box(task, arm)
    f = plane.fixed_axis
    if not lo_box[f] <= plane.fixed_value <= hi_box[f]:
        raise ValueError(f"the task plane ({'xyz'[f]} = {plane.fixed_value:g} mm) is outside workspace_min_mm/"
                         f"workspace_max_mm")
    free = [i for i in range(3) if i != f]
    lo = np.maximum([b[0] for b in plane.bounds], lo_box[free])
    hi = np.minimum([b[1] for b in plane.bounds], hi_box[free])
    if np.any(lo >= hi):
        raise ValueError(f"workspace_min_mm/workspace_max_mm leave nothing of the task plane's bounds "
                         f"{plane.bounds} mm")
    return lo, hi


def safety_box(task: str, arm: MyCobotConfig, margin_mm: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """The flange box of an arm (base frame, mm): configured, or the task plane's bounds widened by ``margin_mm``."""
    plane = kinematics.TASK_PLANES[task]
    free = [i for i in range(3) if i != plane.fixed_axis]
    lo, hi = np.empty(3), np.empty(3)
    lo[free] = [b[0] - margin_mm for b in plane.bounds]
    hi[free] = [b[1] + margin_mm for b in plane.bounds]
    lo[plane.fixed_axis] = plane.fixed_value - margin_mm
    hi[plane.fixed_axis] = plane.fixed_value + margin_mm
    if arm.workspace_min_mm is not None:
        lo = np.asarray(arm.workspace_min_mm, dtype=float)
    if arm.workspace_max_mm is not None:
        hi = np.asarray(arm.workspace_max_mm, dtype=float)
    return lo, hi


def safety_limits(config: RigConfig, name: str) -> SafetyLimits:
    """The :class:`SafetyLimits` of one configured arm."""
    arm = config.arms[name]
    lo, hi = safety_box(config.task, arm)
    return SafetyLimits(workspace_min_mm=tuple(lo), workspace_max_mm=tuple(hi), max_step_deg=arm.max_step_deg,
                        max_lost_frames=config.max_lost_frames)


def _format_errors(err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        msg = e["msg"].removeprefix("Value error, ")
        where = ".".join(str(p) for p in e["loc"])
        # a whole-config check names its keys itself
        lines.append(f"{where}: {msg}" if where else msg)
    return "; ".join(lines)


def parse_rig_config(text: str, where: str = "rig config") -> RigConfig:
    """Validate a rig configuration from JSON text; RigConfigError names ``where`` and each bad key."""
    try:
        return RigConfig.model_validate_json(text)
    except ValidationError as e:
        raise RigConfigError(f"{where}: {_format_errors(e)}") from None


def load_rig_config(path: str | Path) -> RigConfig:
    """Read and validate a rig JSON file; relative camera paths are resolved from the file's folder."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise RigConfigError(f"cannot read rig config {path}: {e.strerror or e}") from None
    cfg = parse_rig_config(text, str(path))
    base = path.resolve().parent
    cam = cfg.camera
    update: dict[str, Any] = {"calibration": str(base / cam.calibration)}
    if isinstance(cam.source, str):
        update["source"] = str(base / cam.source)
    return cfg.model_copy(update={"camera": cam.model_copy(update=update)})


def example_rig_config(task: str = "block_push") -> dict:
    """A documented example configuration (a JSON-ready dict) with the world frame placed like the twin's."""
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; expected one of {TASKS}")
    notes = {
        "world frame": "the table frame, mm here, m in recordings; place it like the twin's: block_push: x to "
                       "Robot2's side, y away from the robots (the block's line at goal_line_m), z up; "
                       "peg_insertion: x from Robot2 (peg) to Robot1 (receptacle), z up, y = z cross x",
        "arms.*.base": "the arm's base frame (our kinematics: z up through J1, x forward at J1 = 0) in the world; "
                       "R = Rz(yaw) Ry(pitch) Rx(roll)",
        "arms.*.workspace_*_mm": "flange box in the arm's base frame (SafeArm); with the task plane's bounds it "
                                 "defines where targets may go (here they keep the two arms apart)",
        "arms.*.port / host": "exactly one: serial port, or the TCP server of a myCobot 280 Pi/JN (netport 9000)",
        "camera.source": "camera index (V4L2) or a video file; calibration from `python -m lfdt.robot calibrate`",
        "camera.table_tag_pose": "the table tag's pose in the world frame (face up on the table: roll = pitch = 0)",
        "camera.object_angle_offset_deg": "the object tag's in-plane angle when the object is at angle 0",
        "control_period_s": "command -> next observation; the twin uses 0.1 s",
        "max_lost_frames": "frames without the needed tags before both arms are stopped",
    }
    if task == "block_push":
        # yaw 90: the arm's forward (base x) is world +y; its flange plane z = 100 mm sweeps y 95..175 mm
        r1 = {"port": "/dev/ttyUSB0", "base": {"x_mm": -60.0, "y_mm": -55.0, "z_mm": 0.0, "yaw_deg": 90.0},
              "workspace_min_mm": [140.0, -50.0, 90.0], "workspace_max_mm": [240.0, 90.0, 110.0]}
        r2 = {"port": "/dev/ttyUSB1", "base": {"x_mm": 60.0, "y_mm": -55.0, "z_mm": 0.0, "yaw_deg": 90.0},
              "workspace_min_mm": [140.0, -90.0, 90.0], "workspace_max_mm": [240.0, 50.0, 110.0]}
        table = {"x_mm": 0.0, "y_mm": 300.0, "z_mm": 0.0}
        extra: dict[str, Any] = {"goal_line_m": 0.20}
    else:
        # tools point along their base +x: Robot2 (peg) faces +x, Robot1 (receptacle) faces -x (yaw 180)
        r1 = {"host": "192.168.1.11", "base": {"x_mm": 305.0, "y_mm": 0.0, "z_mm": -15.0, "yaw_deg": 180.0}}
        r2 = {"host": "192.168.1.12", "base": {"x_mm": -275.0, "y_mm": 0.0, "z_mm": -15.0, "yaw_deg": 0.0}}
        table = {"x_mm": 0.0, "y_mm": 150.0, "z_mm": 150.0, "roll_deg": 90.0}  # upright, facing the camera
        extra = {}
    for arm in (r1, r2):
        arm.update({"speed": 30, "max_step_deg": 15.0})
    return {"_notes": notes, "task": task, "control_period_s": 0.1, "max_lost_frames": 5,
            "max_relative_target_mm": 40.0, "clip_to_workspace": True, **extra, "reset_settle_s": 5.0,
            "arms": {"r1": r1, "r2": r2},
            "camera": {"source": 0, "calibration": "calib.json", "table_tag_id": 0, "table_tag_pose": table,
                       "table_tag_size_m": 0.10, "hand_tag_id": 1, "object_tag_id": 2, "tag_size_m": 0.065,
                       "object_angle_offset_deg": 0.0}}


def write_rig_config(path: str | Path, task: str = "block_push", overwrite: bool = False) -> Path:
    """Write :func:`example_rig_config` as JSON (atomically); FileExistsError unless ``overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists (pass --force to overwrite)")
    text = json.dumps(example_rig_config(task), indent=2) + "\n"
    parse_rig_config(text, "example")  # the example must always be valid
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


# ---------------------------------------------------------------------------------------------------------------
# the rig interface


def plane_angle(rotation: np.ndarray, task: str) -> float:
    """In-plane angle (rad) of a rotation: twist about world +z (block_push) or +y (peg_insertion)."""
    from lfdt.robot.tracker import rotation_about_axis

    axis = (0.0, 0.0, 1.0) if task == "block_push" else (0.0, 1.0, 0.0)
    return rotation_about_axis(rotation, axis)


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


class Rig(ABC):
    """Observe the state of a domain and command its robots, in the twin's conventions (see the module doc)."""

    task: str
    domain: str
    control_dt: float

    def _init_slots(self, task: str, domain: str) -> None:
        if task not in TASKS:
            raise ValueError(f"unknown task {task!r}; expected one of {TASKS}")
        if domain not in layout.DOMAINS:
            raise ValueError(f"unknown domain {domain!r}; expected one of {layout.DOMAINS}")
        self.task, self.domain = task, domain
        self.layout = LAYOUTS[task]
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
    def act(self, relative_targets: Mapping[str, Any]) -> None:
        """Command each robot of the domain to its end's target relative to the last observation (m, 2 numbers)."""

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


# ---------------------------------------------------------------------------------------------------------------
# real robots


class RealRig(Rig):
    """The robots of a domain (R1H: r1, HR2: r2, Y: both) through SafeArm, and the AprilTag tracker."""

    def __init__(self, config: RigConfig, domain: str, *, arms: Mapping[str, Any] | None = None,
                 tracker: Any | None = None, power_on: bool = True) -> None:
        """Connect the domain's arms (or use ``arms``: name -> Arm, wrapped in SafeArm) and open the camera (or use
        ``tracker``). Raises RigConfigError when the configuration lacks an arm the domain needs."""
        self._init_slots(config.task, domain)
        missing = [a for a in self.robots if a not in config.arms]
        if missing:
            raise RigConfigError(f"domain {domain} needs arms.{missing[0]} in the rig config")
        self.config = config
        self.control_dt = config.control_period_s
        self.plane = kinematics.TASK_PLANES[config.task]
        self.arms: dict[str, SafeArm] = {}
        self._closed = False
        self.tracker = None
        try:
            for name in self.robots:
                raw = arms[name] if arms is not None else self._connect(name)
                self.arms[name] = SafeArm(raw, safety_limits(config, name))
                if power_on:
                    self.arms[name].power_on()
            self.tracker = tracker if tracker is not None else self._open_camera()
        except BaseException:
            self.close()
            raise
        self._world_from_base = {n: config.arms[n].base.matrix() for n in self.robots}
        self._bounds = {n: workspace_bounds(config.task, config.arms[n]) for n in self.robots}
        self._angles: dict[str, np.ndarray] = {}
        self._lost = 0
        self._last_act: float | None = None

    def _connect(self, name: str):
        from lfdt.robot.arm import MyCobotArm

        a = self.config.arms[name]
        return MyCobotArm.connect(port=a.port, host=a.host, netport=a.netport, baudrate=a.baudrate,
                                  timeout_s=a.connect_timeout_s)

    def _open_camera(self):
        import cv2

        from lfdt.robot.tracker import Tracker

        cam = self.config.camera
        sizes = {} if cam.table_tag_size_m is None else {cam.table_tag_id: cam.table_tag_size_m}
        tracker = Tracker(cam.source, cam.calibration, table_tag_id=cam.table_tag_id,
                          table_tag_in_base=cam.table_tag_pose.matrix(1e-3), hand_tag_id=cam.hand_tag_id,
                          object_tag_id=cam.object_tag_id, tag_size_m=cam.tag_size_m, tag_sizes_m=sizes)
        # a live camera's driver queues frames; a short queue keeps observations fresh
        tracker.capture.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        return tracker

    # ---- geometry

    def end_world_mm(self, name: str, angles_deg) -> np.ndarray:
        """Flange position (mm, 3D) of arm ``name`` at ``angles_deg``, in the world frame."""
        p = kinematics.position(angles_deg, self.arms[name].limits.dh)
        return (self._world_from_base[name] @ np.append(p, 1.0))[:3]

    def plane_point_in_base(self, name: str, target_world_2d_mm: np.ndarray) -> np.ndarray:
        """The point of arm ``name``'s task plane whose world task-plane coordinates are given, in its base frame."""
        t = self._world_from_base[name]
        rot, trans = t[:3, :3], t[:3, 3]
        f = self.plane.fixed_axis
        a = self.plane.to_3d(np.asarray(target_world_2d_mm, dtype=float))
        a[f] = 0.0
        # solve for the world fixed coordinate s so that the point lies on the arm's plane (base[f] = fixed_value)
        s = (self.plane.fixed_value - (rot.T @ (a - trans))[f]) / rot[f, f]
        a[f] = s
        return rot.T @ (a - trans)

    # ---- observe

    def _tracked(self):
        needs_hand = self.human_slot is not None
        while True:
            frame = self.tracker.read()
            if frame is None:
                raise RuntimeError("the camera gave no frame (video ended or camera disconnected)")
            if frame.object_pose is not None and (not needs_hand or frame.hand_position is not None):
                self._lost = 0
                return frame
            self._lost += 1
            if self._lost > self.config.max_lost_frames:
                self._tracking_lost()

    def _tracking_lost(self) -> None:
        lost: TrackingLost | None = None
        for arm in self.arms.values():  # every arm is stopped, even after the first one raised
            try:
                arm.tracking_lost(self._lost)
            except TrackingLost as e:
                lost = e
        if lost is None:  # an arm configured more tolerant than the rig: the rig's limit still holds
            self.stop()
            lost = TrackingLost(f"tracking lost for {self._lost} frames: arms stopped")
        need = "object and hand" if self.human_slot is not None else "object"
        raise TrackingLost(f"{lost} (the {need} tags were not seen)")

    def observe(self) -> np.ndarray:
        """Wait out the control period since the last command, read the arms' angles and the camera."""
        if self._last_act is not None:
            wait = self._last_act + self.control_dt - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        self._angles = {n: np.asarray(self.arms[n].get_angles(), dtype=float) for n in self.robots}
        frame = self._tracked()
        out = []
        for arm in self.slots:
            if arm == "h":
                out.append(self.plane.to_2d(frame.hand_position))
            else:
                out.append(self.plane.to_2d(self.end_world_mm(arm, self._angles[arm])) * 1e-3)
        pose = frame.object_pose
        angle = _wrap(plane_angle(pose.pose[:3, :3], self.task)
                      - math.radians(self.config.camera.object_angle_offset_deg))
        out.append(np.array([*self.plane.to_2d(pose.position), angle]))
        return np.concatenate(out)

    # ---- act

    def plan(self, name: str, relative_target_m: np.ndarray) -> list[float]:
        """Joint angles for one robot's relative target, validated by SafeArm (SafetyError names the arm)."""
        cfg = self.config
        rel = np.asarray(relative_target_m, dtype=float) * 1e3
        if not np.all(np.isfinite(rel)):
            raise SafetyError(f"{name}: relative target {relative_target_m} is not finite")
        if float(np.linalg.norm(rel)) > cfg.max_relative_target_mm:
            raise SafetyError(f"{name}: relative target of {np.linalg.norm(rel):.1f} mm is longer than "
                              f"max_relative_target_mm {cfg.max_relative_target_mm:g}")
        angles = self._angles.get(name)
        if angles is None:  # act() without a fresh observe(): start from where the arm is now
            angles = np.asarray(self.arms[name].get_angles(), dtype=float)
            self._angles[name] = angles
        target_w = self.plane.to_2d(self.end_world_mm(name, angles)) + rel
        target_b = self.plane_point_in_base(name, target_w)
        free = [i for i in range(3) if i != self.plane.fixed_axis]
        lo, hi = self._bounds[name]
        inside = np.clip(target_b[free], lo, hi)
        if not np.allclose(inside, target_b[free]):
            if not cfg.clip_to_workspace:
                raise SafetyError(f"{name}: target {np.round(target_b, 1)} mm (base frame) is outside the "
                                  f"workspace {lo.round(1).tolist()}..{hi.round(1).tolist()} mm")
            target_b[free] = inside
        try:
            q = kinematics.inverse(target_b, self.plane.tool_axis, angles, self.arms[name].limits.dh)
        except ValueError as e:
            raise SafetyError(f"{name}: {e}") from None
        try:
            return self.arms[name].check(q, cfg.arms[name].speed)
        except SafetyError as e:
            raise SafetyError(f"{name}: {e}") from None

    def act(self, relative_targets: Mapping[str, Any]) -> None:
        """Plan every robot's command first, then send them: one refusal sends nothing to any arm."""
        targets = self._targets(relative_targets)
        plans = {name: self.plan(name, rel) for name, rel in targets.items()}
        for name, q in plans.items():
            self.arms[name].send_angles(q, self.config.arms[name].speed)
        self._angles = {}
        self._last_act = time.monotonic()

    # ---- reset, stop, close

    def start_angles(self, name: str) -> np.ndarray:
        """Where reset() brings arm ``name``."""
        a = self.config.arms[name].start_angles_deg
        return kinematics.home_angles(self.task) if a is None else np.asarray(a, dtype=float)

    def _reset_path(self, name: str) -> list[np.ndarray]:
        """Joint targets taking arm ``name`` from where it is to its start angles along a straight flange path
        (10 mm steps, so that it stays inside its tight workspace box), ending exactly at the start angles."""
        arm, speed = self.arms[name], self.config.arms[name].speed
        arm.last_command = None  # the first step is checked against the measured angles
        now = np.asarray(arm.get_angles(), dtype=float)
        goal = self.start_angles(name)
        try:
            check_command(now, speed, replace(arm.limits, max_step_deg=None))
        except SafetyError as e:
            angles = " ".join(f"{a:.1f}" for a in goal)
            raise SafetyError(f"{name} is not inside its workspace ({e}); bring it to its start angles first, "
                              f"e.g. python -m lfdt.robot move --port ... --angles {angles} --speed 20") from None
        p0, p1 = (kinematics.position(q, arm.limits.dh) for q in (now, goal))
        n = max(1, math.ceil(float(np.linalg.norm(p1 - p0)) / 10.0))
        path, q = [], now
        for i in range(1, n):
            try:
                q = kinematics.inverse(p0 + (p1 - p0) * i / n, self.plane.tool_axis, q, arm.limits.dh)
            except ValueError as e:
                raise SafetyError(f"{name}: reset path: {e}") from None
            path.append(q)
        return [*path, goal]

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Bring the robots to their start angles (every command through SafeArm), wait until they are there (at
        most reset_settle_s), then observe. ``seed`` is ignored: on the robots the operator sets the scene."""
        paths = {n: self._reset_path(n) for n in self.robots}
        for i in range(max(len(p) for p in paths.values())):
            for n, p in paths.items():
                if i < len(p):
                    self.arms[n].send_angles(p[i], self.config.arms[n].speed)
            time.sleep(self.control_dt)
        deadline = time.monotonic() + self.config.reset_settle_s
        while time.monotonic() < deadline:
            if all(np.max(np.abs(np.asarray(self.arms[n].get_angles()) - p[-1])) < 1.0 for n, p in paths.items()):
                break
            time.sleep(0.1)
        self._lost, self._last_act, self._angles = 0, None, {}
        return self.observe()

    def stop(self) -> None:
        """Stop every arm, trying all of them even if one fails."""
        error: BaseException | None = None
        for arm in self.arms.values():
            try:
                arm.stop()
            except Exception as e:  # noqa: PERF203 - each arm must get its stop
                error = e
        if error is not None:
            raise error

    def close(self) -> None:
        """Close the arms and the camera (twice is fine)."""
        if self._closed:
            return
        self._closed = True
        for arm in self.arms.values():
            try:
                arm.close()
            except Exception:  # noqa: S110 - closing the others matters more
                pass
        if self.tracker is not None:
            self.tracker.close()


# ---------------------------------------------------------------------------------------------------------------
# the twin


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
