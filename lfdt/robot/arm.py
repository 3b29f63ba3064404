"""The arm interface: a myCobot 280 over pymycobot, a simulated arm, and a safety layer in front of either.

* :class:`MyCobotArm` wraps pymycobot's ``MyCobot280`` (serial) or ``MyCobot280Socket`` (TCP) and turns its
  silent failures (``-1``, ``None``, short lists) into :class:`ArmNotResponding`.
* :class:`SimArm` holds joint angles and follows commands with a lag, for dry runs and tests.
* :class:`SafeArm` validates every command (joint limits, speed, flange workspace box, largest step per joint)
  before anything is sent, stops the arm when tracking is lost, and :func:`lfdt.rig.interrupt.stop_on_interrupt`
  stops and closes it on Ctrl-C.

pymycobot's timing (4.0.7): the constructors sleep 1.5 s; each synchronous command waits for a reply whose 4th
byte is the command code, 0.5 s (serial) or 0.3 s (TCP) per try, 3 tries, re-sending the command each try, then
returns -1. Creating a pymycobot object also configures the *root* logger (a stderr handler at WARNING) when the
application has not configured logging yet.
"""

from __future__ import annotations

import math
import numbers
import socket
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

from lfdt.robot.kinematics import DH, JOINT_LIMITS_DEG, position


class ArmNotResponding(RuntimeError):
    """The arm did not answer, answered garbage, or could not be reached; the message names the port or host."""


class SafetyError(ValueError):
    """A command was refused by :class:`SafeArm`; nothing was sent to the arm."""


class TrackingLost(RuntimeError):
    """Tracking was lost for more frames than allowed; the arm has been stopped."""


@runtime_checkable
class Arm(Protocol):
    """What the rest of the code needs from one arm. Angles in degrees, joints J1..J6."""

    def get_angles(self) -> list[float]:
        """Current joint angles, 6 values in degrees."""
        ...

    def send_angles(self, angles: Sequence[float], speed: int) -> None:
        """Start moving to ``angles`` (degrees) at ``speed`` (1..100); returns without waiting for arrival."""
        ...

    def power_on(self) -> None:
        """Power the servos."""
        ...

    def stop(self) -> None:
        """Stop the current motion."""
        ...

    def close(self) -> None:
        """Release the connection."""
        ...


def _format_angles(angles: Sequence[float]) -> str:
    return " ".join(f"{a:.2f}" for a in angles)


# ---------------------------------------------------------------------------------------------------------------
# pymycobot


def _socket_class(connect_timeout_s: float) -> type:
    from pymycobot import MyCobot280Socket as _Base

    # pymycobot's connect_socket has no timeout (a black-holed host blocks for minutes). The subclass must keep the
    # name MyCobot280Socket: pymycobot validates arguments by looking up limits under the class name.
    class MyCobot280Socket(_Base):
        def connect_socket(self) -> socket.socket:
            return socket.create_connection((self.SERVER_IP, self.SERVER_PORT), timeout=connect_timeout_s)

    return MyCobot280Socket


class MyCobotArm:
    """One myCobot 280 through pymycobot (``MyCobot280`` over serial or ``MyCobot280Socket`` over TCP).

    Build it with :meth:`connect`. Every call that gets no sensible answer raises :class:`ArmNotResponding`.
    """

    def __init__(self, robot: Any, where: str, *, require_ack: bool = True) -> None:
        """Wrap an already constructed pymycobot object; ``where`` names its port or host in error messages.

        ``require_ack``: treat a command that got no status reply (pymycobot returns -1) as a failure. Firmware
        that never acknowledges commands needs ``False``; pymycobot then sends each command 3 times.
        """
        self.robot = robot
        self.where = where
        self.require_ack = require_ack
        self._closed = False

    @classmethod
    def connect(cls, port: str | None = None, host: str | None = None, netport: int = 9000, baudrate: int = 115200,
                timeout_s: float = 3.0, require_ack: bool = True) -> MyCobotArm:
        """Open a serial ``port`` or a TCP connection to ``host:netport``; exactly one of port/host.

        ``timeout_s`` bounds the TCP connection attempt (the serial open does not block). Does not talk to the arm
        (pymycobot only sleeps 1.5 s): a silent arm shows up at the first command. Raises ArmNotResponding when the
        port cannot be opened or the host refuses / does not answer.
        """
        if (port is None) == (host is None):
            raise ValueError("give exactly one of port (serial) or host (TCP)")
        if port is not None:
            where = f"serial port {port} ({baudrate} baud)"
            from pymycobot import MyCobot280

            try:
                robot = MyCobot280(port, baudrate)
            except OSError as e:  # serial.SerialException is an OSError
                raise ArmNotResponding(f"cannot open {where}: {e}") from e
        else:
            where = f"{host}:{netport}"
            try:
                robot = _socket_class(timeout_s)(host, netport)
            except OSError as e:  # refused, unreachable, timed out, unknown host
                raise ArmNotResponding(f"cannot connect to the myCobot at {where}: {e}") from e
        return cls(robot, where, require_ack=require_ack)

    def _call(self, what: str, fn, *args) -> Any:
        if self._closed:
            raise ArmNotResponding(f"the connection to {self.where} is closed")
        try:
            return fn(*args)
        except OSError as e:  # a dropped TCP connection or an unplugged USB cable
            raise ArmNotResponding(f"{what}: lost the connection to the myCobot at {self.where}: {e}") from e
        except (struct.error, IndexError) as e:  # pymycobot's parser chokes on malformed replies
            raise ArmNotResponding(f"{what}: garbled reply from the myCobot at {self.where}: {e}") from e

    def _acked(self, what: str, result: Any) -> None:
        if self.require_ack and (result is None or result == -1):
            raise ArmNotResponding(f"{what}: no reply from the myCobot at {self.where} (pymycobot returned "
                                   f"{result!r} after 3 tries)")

    def get_angles(self) -> list[float]:
        """Joint angles in degrees; raises ArmNotResponding instead of returning pymycobot's -1 / [] / short list."""
        result = self._call("GET_ANGLES", self.robot.get_angles)
        if not isinstance(result, list) or len(result) != 6 or not all(isinstance(a, int | float) for a in result):
            raise ArmNotResponding(f"GET_ANGLES: no valid answer from the myCobot at {self.where} "
                                   f"(pymycobot returned {result!r}); is it powered and connected?")
        return [float(a) for a in result]

    def send_angles(self, angles: Sequence[float], speed: int) -> None:
        """Send a joint target (degrees) at ``speed`` 1..100; no safety checks here (see SafeArm)."""
        values = [float(a) for a in angles]
        if len(values) != 6:
            raise ValueError(f"need 6 angles, got {len(values)}")
        self._acked("SEND_ANGLES", self._call("SEND_ANGLES", self.robot.send_angles, values, int(speed)))

    def power_on(self) -> None:
        """Power the servos (POWER_ON)."""
        self._acked("POWER_ON", self._call("POWER_ON", self.robot.power_on))

    def is_power_on(self) -> bool:
        """Whether the servos are powered (IS_POWER_ON)."""
        result = self._call("IS_POWER_ON", self.robot.is_power_on)
        if result not in (0, 1):
            raise ArmNotResponding(f"IS_POWER_ON: no valid answer from the myCobot at {self.where} "
                                   f"(pymycobot returned {result!r})")
        return result == 1

    def stop(self) -> None:
        """Stop the current motion (STOP)."""
        self._acked("STOP", self._call("STOP", self.robot.stop))

    def close(self) -> None:
        """Close the serial port / socket; safe to call twice."""
        if not self._closed:
            self._closed = True
            self.robot.close()


# ---------------------------------------------------------------------------------------------------------------
# simulation


class SimArm:
    """A simulated arm: each ``send_angles`` moves every joint toward the target by at most ``max_step_deg``.

    The lag stands in for the real arm still being on its way when the next command comes; ``speed`` is recorded
    but does not change the step. Counts ``stop``/``close`` calls so tests can assert on them.
    """

    def __init__(self, angles: Sequence[float] | None = None, max_step_deg: float = 5.0) -> None:
        """Start at ``angles`` (default zeros), following targets by at most ``max_step_deg`` per command."""
        self.angles = [0.0] * 6 if angles is None else [float(a) for a in angles]
        if len(self.angles) != 6:
            raise ValueError(f"need 6 angles, got {len(self.angles)}")
        self.max_step_deg = float(max_step_deg)
        self.target: list[float] | None = None
        self.commands: list[tuple[list[float], int]] = []
        self.powered = False
        self.stop_count = 0
        self.closed = False

    def get_angles(self) -> list[float]:
        """Current angles (degrees)."""
        return list(self.angles)

    def send_angles(self, angles: Sequence[float], speed: int) -> None:
        """Record the command and take one lagged step toward it."""
        target = [float(a) for a in angles]
        if len(target) != 6:
            raise ValueError(f"need 6 angles, got {len(target)}")
        self.commands.append((target, int(speed)))
        self.target = target
        self.step()

    def step(self) -> None:
        """Move one step toward the current target (also what a control loop tick would do)."""
        if self.target is None:
            return
        m = self.max_step_deg
        self.angles = [a + max(-m, min(m, t - a)) for a, t in zip(self.angles, self.target)]

    def power_on(self) -> None:
        """Mark the servos powered."""
        self.powered = True

    def stop(self) -> None:
        """Forget the target: the arm stays where it is."""
        self.stop_count += 1
        self.target = None

    def close(self) -> None:
        """Mark closed."""
        self.closed = True


# ---------------------------------------------------------------------------------------------------------------
# safety


@dataclass(frozen=True)
class SafetyLimits:
    """What :class:`SafeArm` allows. The defaults are a loose envelope around one myCobot 280 (reach ~280 mm,
    flange straight up at ~411 mm): tighten ``workspace_*`` per task."""

    joint_limits_deg: tuple[tuple[float, float], ...] = JOINT_LIMITS_DEG
    workspace_min_mm: tuple[float, float, float] = (-350.0, -350.0, 40.0)
    """Smallest flange x, y, z (base frame, mm); z keeps the flange off the mounting surface."""
    workspace_max_mm: tuple[float, float, float] = (350.0, 350.0, 500.0)
    max_step_deg: float | None = 20.0
    """Largest change of any joint in one command (None: unchecked)."""
    speed_range: tuple[int, int] = (1, 100)
    max_lost_frames: int = 5
    """Frames without tracking tolerated before :meth:`SafeArm.tracking_lost` stops the arm."""
    dh: DH = field(default_factory=DH)


EDGE_TOLERANCE_MM = 0.1
"""A flange this little outside the workspace box counts as on its edge: the arms report angles in 0.01 deg steps,
which moves the flange by up to ~0.05 mm per joint, and an arm resting on the edge must not be refused there."""


def _fmt(x: float) -> str:
    return f"{x:g}"


def check_command(angles: Sequence[float], speed: int, limits: SafetyLimits = SafetyLimits(),
                  current: Sequence[float] | None = None) -> list[float]:
    """Validate one joint command without touching any arm; returns the angles as floats.

    Checks, in order: 6 finite angles, speed, joint limits, flange inside the workspace box, and (when ``current``
    is given and ``limits.max_step_deg`` is set) the change per joint. Raises SafetyError naming the joint or axis.
    """
    values = [float(a) for a in angles]
    if len(values) != 6:
        raise SafetyError(f"need 6 joint angles, got {len(values)}")
    for j, a in enumerate(values, start=1):
        if not math.isfinite(a):
            raise SafetyError(f"J{j} = {a} is not a finite angle")
    lo_speed, hi_speed = limits.speed_range
    if isinstance(speed, bool) or not isinstance(speed, numbers.Integral) or not lo_speed <= speed <= hi_speed:
        raise SafetyError(f"speed {speed!r} outside {lo_speed}..{hi_speed}")
    for j, (a, (lo, hi)) in enumerate(zip(values, limits.joint_limits_deg), start=1):
        if not lo <= a <= hi:
            raise SafetyError(f"J{j} = {a:.1f} deg outside [{_fmt(lo)}, {_fmt(hi)}]")
    p = position(values, limits.dh)
    for axis, v, lo, hi in zip("xyz", p, limits.workspace_min_mm, limits.workspace_max_mm):
        if v < lo - EDGE_TOLERANCE_MM:
            raise SafetyError(f"{axis} = {v:.1f} mm below the workspace minimum {lo:.1f} mm "
                              f"(flange at {_format_angles(values)} deg)")
        if v > hi + EDGE_TOLERANCE_MM:
            raise SafetyError(f"{axis} = {v:.1f} mm above the workspace maximum {hi:.1f} mm "
                              f"(flange at {_format_angles(values)} deg)")
    if current is not None and limits.max_step_deg is not None:
        for j, (a, c) in enumerate(zip(values, current), start=1):
            if abs(a - c) > limits.max_step_deg:
                raise SafetyError(f"J{j} would change by {a - c:+.1f} deg in one command (from {c:.1f} to {a:.1f}), "
                                  f"more than the maximum step {limits.max_step_deg:.1f} deg")
    return values


class SafeArm:
    """Any :class:`Arm` behind a validator: a refused command raises SafetyError and reaches nothing.

    The step limit compares with the last command that went through (or, before the first one, with the angles read
    from the arm): it catches jumps in the command stream such as an IK branch flip.
    """

    def __init__(self, arm: Arm, limits: SafetyLimits = SafetyLimits()) -> None:
        """Wrap ``arm`` with ``limits``."""
        self.arm = arm
        self.limits = limits
        self.last_command: list[float] | None = None

    def check(self, angles: Sequence[float], speed: int) -> list[float]:
        """Validate a command against the limits (reads the arm's angles once, for the first step check)."""
        current = self.last_command
        if current is None and self.limits.max_step_deg is not None:
            current = self.arm.get_angles()
        return check_command(angles, speed, self.limits, current)

    def send_angles(self, angles: Sequence[float], speed: int) -> None:
        """Validate, then send; raises SafetyError (nothing sent) when refused."""
        values = self.check(angles, speed)
        self.arm.send_angles(values, speed)
        self.last_command = values

    def get_angles(self) -> list[float]:
        """The wrapped arm's angles."""
        return self.arm.get_angles()

    def power_on(self) -> None:
        """Power the wrapped arm."""
        self.arm.power_on()

    def stop(self) -> None:
        """Stop the wrapped arm; the next command is step-checked against the measured angles again."""
        self.last_command = None
        self.arm.stop()

    def close(self) -> None:
        """Close the wrapped arm."""
        self.arm.close()

    def tracking_lost(self, frames_without_tracking: int) -> None:
        """Report how many consecutive frames had no tracking; above ``max_lost_frames`` stop and raise TrackingLost."""
        if frames_without_tracking > self.limits.max_lost_frames:
            self.stop()
            raise TrackingLost(f"tracking lost for {frames_without_tracking} frames (at most "
                               f"{self.limits.max_lost_frames} allowed): arm stopped")


