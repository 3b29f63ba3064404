"""The real robots behind the rig interface: two myCobot 280 arms through the safety layer and the AprilTag
tracker (conventions: :mod:`lfdt.rig.base`)."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from lfdt.rig.base import Rig, _wrap, plane_angle
from lfdt.robot import kinematics
from lfdt.robot.arm import SafeArm, SafetyError, TrackingLost, check_command
from lfdt.robot.rig_config import RigConfig, RigConfigError, safety_limits, workspace_bounds

CLIP_MARGIN_MM = 1.0
"""Targets outside an arm's workspace are clipped this far inside its edges, so that IK and the arm's angle rounding
never leave the flange on the wrong side of the safety box."""


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
        try:
            tracker = Tracker(cam.source, cam.calibration, table_tag_id=cam.table_tag_id,
                              table_tag_in_base=cam.table_tag_pose.matrix(1e-3), hand_tag_id=cam.hand_tag_id,
                              object_tag_id=cam.object_tag_id, tag_size_m=cam.tag_size_m, tag_sizes_m=sizes)
        except (OSError, RuntimeError, ValueError, KeyError, TypeError) as e:
            # a camera that exists but cannot be opened (busy, unplugged since the check), a file OpenCV cannot read
            raise RigConfigError(f"camera.source {cam.source} (calibration {cam.calibration}): cannot open the "
                                 f"camera: {e}") from None
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
        if np.any(target_b[free] < lo) or np.any(target_b[free] > hi):
            if not cfg.clip_to_workspace:
                raise SafetyError(f"{name}: target {np.round(target_b, 1)} mm (base frame) is outside the "
                                  f"workspace {lo.round(1).tolist()}..{hi.round(1).tolist()} mm")
            margin = np.minimum(CLIP_MARGIN_MM, (hi - lo) / 2)
            target_b[free] = np.clip(target_b[free], lo + margin, hi - margin)
        try:
            q = kinematics.inverse(target_b, self.plane.tool_axis, angles, self.arms[name].limits.dh)
        except ValueError as e:
            raise SafetyError(f"{name}: {e}") from None
        try:
            return self.arms[name].check(q, cfg.arms[name].speed)
        except SafetyError as e:
            raise SafetyError(f"{name}: {e}") from None

    def act(self, relative_targets: Mapping[str, Any], human_target: Any = None) -> None:
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
