"""Configuration of the real rig: where each myCobot 280 is connected and stands, the camera and its tags, and
what the safety layer allows (``rig.json``; ``python -m lfdt.robot write-rig-config`` writes an example)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from lfdt import inputs
from lfdt.errors import InputError
from lfdt.files import temp_path
from lfdt.robot import kinematics
from lfdt.robot.arm import SafetyLimits
from lfdt.tasks import registry


class RigConfigError(InputError, ValueError):
    """A rig configuration file that cannot be used; the message names the file and the key."""


# ---------------------------------------------------------------------------------------------------------------
# configuration


class _Model(BaseModel):
    # strict: a quoted number or a list where an object belongs is an error, not silently converted; no NaN or
    # infinity (an infinite max_step_deg would be no limit at all)
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, use_attribute_docstrings=True,
                              populate_by_name=True, allow_inf_nan=False)


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

    port: Annotated[str, Field(min_length=1)] | None = None
    """Serial port (e.g. /dev/ttyUSB0); give exactly one of port and host."""
    host: Annotated[str, Field(min_length=1)] | None = None
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
    task: str
    """The real task (:mod:`lfdt.tasks`; the arms' plane and tool orientation for it: kinematics.TASK_PLANES)."""
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
        if self.task not in registry.PLANAR or self.task not in kinematics.TASK_PLANES:
            known = [t for t in registry.PLANAR if t in kinematics.TASK_PLANES]
            raise ValueError(f"task: {self.task!r} is not a real-robot task the arms are set up for; expected one "
                             f"of {known}")
        plane = kinematics.TASK_PLANES[self.task]
        f = plane.fixed_axis
        connections: dict[str, str] = {}
        for name, arm in self.arms.items():
            # two arms on one connection would send both arms' commands to one of them
            where = arm.port if arm.port is not None else f"{arm.host}:{arm.netport}"
            if where in connections:
                raise ValueError(f"arms.{connections[where]} and arms.{name} are both connected at {where!r}; each "
                                 "arm has its own serial port or TCP server")
            connections[where] = name
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
        cfg = RigConfig.model_validate_json(text)
    except ValidationError as e:
        raise RigConfigError(f"{where}: {_format_errors(e)}") from None
    twice = inputs.duplicate_json_key(text)  # valid JSON by now
    if twice is not None:
        raise RigConfigError(f"{where}: has the key {twice!r} twice in one object; keep one")
    return cfg


def load_rig_config(path: str | Path) -> RigConfig:
    """Read and validate a rig JSON file; relative camera paths are resolved from the file's folder. The camera's
    own files are checked by :func:`check_camera` (the robots need them, a dry run on the twin does not)."""
    path = Path(path)
    try:
        text = inputs.read_text(path, "rig config", "a rig JSON (python -m lfdt.robot write-rig-config)")
    except InputError as e:
        raise RigConfigError(f"cannot read {e}") from None
    cfg = parse_rig_config(text, str(path))
    base = path.resolve().parent
    cam = cfg.camera
    update: dict[str, Any] = {"calibration": str(base / cam.calibration)}
    if isinstance(cam.source, str):
        update["source"] = str(base / cam.source)
    return cfg.model_copy(update={"camera": cam.model_copy(update=update)})


def check_camera(cfg: RigConfig, where: str | Path) -> None:
    """Before anything moves: the calibration file is a camera calibration (not missing, empty, garbage or JSON of
    another shape) and the camera source exists (a video file, or on Linux the device of a camera index).
    RigConfigError names the rig config ``where``, the key and the file."""
    from lfdt.robot.calibration import CameraCalibration  # OpenCV: only for the robots

    cam = cfg.camera
    inputs.json_object(cam.calibration, f"{where}: camera.calibration", "a camera calibration JSON (python -m "
                       "lfdt.robot calibrate --out ...)", CameraCalibration.from_dict, error=RigConfigError)
    if isinstance(cam.source, str):
        inputs.readable_file(cam.source, f"{where}: camera.source", "a video file, or a camera index such as 0",
                             error=RigConfigError)
    else:
        inputs.camera_device(cam.source, f"{where}: camera.source", error=RigConfigError)


def example_rig_config(task: str = "block_push") -> dict:
    """A documented example configuration (a JSON-ready dict) with the world frame placed like the twin's."""
    registry.get(task)  # an unknown task fails here, naming the known ones
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
    r1, r2, table, extra = registry.get(task).example_rig()
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
    tmp = temp_path(path)
    tmp.write_text(text)
    os.replace(tmp, path)
    return path
