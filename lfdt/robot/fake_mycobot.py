"""A fake myCobot 280 speaking the real serial/TCP frame protocol, for tests and dry runs without hardware.

Frames are ``FE FE LEN CMD payload FA`` with ``LEN = len(payload) + 2``; values are big-endian int16,
angles in degrees x 100, x/y/z in mm x 10 (pymycobot's encoding). The peer answers the way pymycobot 4.0's
``MyCobot280`` / ``MyCobot280Socket`` parse replies:

* GET_ANGLES (0x20) / GET_COORDS (0x23): 12 bytes (six int16);
* IS_POWER_ON (0x12), IS_CONTROLLER_CONNECTED (0x14): one byte, 1 or 0;
* commands that set something (POWER_ON 0x10, SEND_ANGLES 0x22, SEND_COORDS 0x25, STOP 0x29, ...): a one-byte
  status ``FE FE 03 CMD 01 FA``. pymycobot's ``MyCobot280`` waits for a reply to *every* synchronous command and
  re-sends the command up to 3 times when none comes, so a peer that stays quiet after SEND_ANGLES would receive it
  three times. ``ack=False`` reproduces that quiet behaviour.

Unknown commands are recorded and not answered. ``silent=True`` records everything and answers nothing (a
powered-off arm or a wrong port). Two transports: a pseudo-terminal (pass :attr:`FakeMyCobot.device` as the serial
port) and a loopback TCP server (:attr:`FakeMyCobot.port`, for ``MyCobot280Socket``).

Coordinates are this package's kinematics (flange position, roll-pitch-yaw ``R = Rz Ry Rx`` in degrees), not the
firmware's: good enough for protocol tests, not for calibration. SEND_COORDS solves our inverse kinematics for the
position and tool axis; when that fails the fake does not move (the firmware flags an error and stays).

Run ``python -m lfdt.robot.fake_mycobot --pty`` (or ``--tcp PORT``) to dry-run the CLI without an arm.
"""

from __future__ import annotations

import argparse
import math
import os
import select
import signal
import socket
import struct
import sys
import threading
import time
import tty
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from lfdt.robot import kinematics

HEADER = 0xFE
FOOTER = 0xFA

POWER_ON = 0x10
POWER_OFF = 0x11
IS_POWER_ON = 0x12
RELEASE_ALL_SERVOS = 0x13
IS_CONTROLLER_CONNECTED = 0x14
GET_ANGLES = 0x20
SEND_ANGLE = 0x21
SEND_ANGLES = 0x22
GET_COORDS = 0x23
SEND_COORD = 0x24
SEND_COORDS = 0x25
PAUSE = 0x26
RESUME = 0x28
STOP = 0x29

COMMAND_NAMES: dict[int, str] = {
    POWER_ON: "POWER_ON", POWER_OFF: "POWER_OFF", IS_POWER_ON: "IS_POWER_ON", RELEASE_ALL_SERVOS: "RELEASE_ALL_SERVOS",
    IS_CONTROLLER_CONNECTED: "IS_CONTROLLER_CONNECTED", GET_ANGLES: "GET_ANGLES", SEND_ANGLE: "SEND_ANGLE",
    SEND_ANGLES: "SEND_ANGLES", GET_COORDS: "GET_COORDS", SEND_COORD: "SEND_COORD", SEND_COORDS: "SEND_COORDS",
    PAUSE: "PAUSE", RESUME: "RESUME", STOP: "STOP",
}
"""Commands the fake understands (codes as in pymycobot's ``ProtocolCode``)."""

_ACKED = {POWER_ON, POWER_OFF, RELEASE_ALL_SERVOS, SEND_ANGLE, SEND_ANGLES, SEND_COORD, SEND_COORDS, PAUSE, RESUME,
          STOP}


def encode_frame(cmd: int, payload: bytes = b"") -> bytes:
    """One protocol frame: ``FE FE LEN CMD payload FA``."""
    return bytes([HEADER, HEADER, len(payload) + 2, cmd]) + payload + bytes([FOOTER])


def encode_int16(values: Iterable[float], scale: float) -> bytes:
    """Big-endian int16s of ``value * scale``, truncated toward zero like pymycobot's ``_angle2int``."""
    return b"".join(struct.pack(">h", int(v * scale)) for v in values)


def decode_int16(data: bytes, scale: float) -> list[float]:
    """Big-endian int16s divided by ``scale``."""
    return [v / scale for (v,) in struct.iter_unpack(">h", data[: len(data) // 2 * 2])]


def parse_frames(buffer: bytearray) -> list[tuple[int, bytes]]:
    """Cut every complete frame off the front of ``buffer`` (in place); returns ``(cmd, payload)`` pairs.

    Bytes that cannot start a frame are dropped one at a time, so the parser resynchronises after garbage.
    """
    frames = []
    while True:
        start = buffer.find(bytes([HEADER, HEADER]))
        if start < 0:
            # keep a trailing FE: it may be the first half of the next header
            del buffer[: max(len(buffer) - 1, 0) if buffer.endswith(bytes([HEADER])) else len(buffer)]
            return frames
        del buffer[:start]
        if len(buffer) < 3:
            return frames
        length = buffer[2]
        if length < 2:
            del buffer[:1]
            continue
        if len(buffer) < length + 3:
            return frames
        if buffer[length + 2] != FOOTER:
            del buffer[:1]
            continue
        frames.append((buffer[3], bytes(buffer[4: length + 2])))
        del buffer[: length + 3]


def _rpy_deg(rot: np.ndarray) -> list[float]:
    # R = Rz(rz) Ry(ry) Rx(rx): the fixed-axis roll-pitch-yaw myCobot reports
    ry = math.asin(max(-1.0, min(1.0, -rot[2, 0])))
    rx = math.atan2(rot[2, 1], rot[2, 2])
    rz = math.atan2(rot[1, 0], rot[0, 0])
    return [math.degrees(a) for a in (rx, ry, rz)]


def _tool_axis(rpy_deg: Sequence[float]) -> np.ndarray:
    rx, ry, rz = np.radians(rpy_deg)
    # third column of Rz Ry Rx: where the flange z axis points
    return np.array([math.cos(rz) * math.sin(ry) * math.cos(rx) + math.sin(rz) * math.sin(rx),
                     math.sin(rz) * math.sin(ry) * math.cos(rx) - math.cos(rz) * math.sin(rx),
                     math.cos(ry) * math.cos(rx)])


@dataclass(frozen=True)
class ReceivedCommand:
    """One frame the fake received."""

    cmd: int
    payload: bytes
    time: float

    @property
    def name(self) -> str:
        """Command name (``UNKNOWN_0xNN`` for codes the fake does not know)."""
        return COMMAND_NAMES.get(self.cmd, f"UNKNOWN_0x{self.cmd:02X}")

    def describe(self) -> str:
        """Human-readable line, with angles/coords decoded."""
        if self.cmd == SEND_ANGLES and len(self.payload) >= 13:
            values = " ".join(f"{a:.2f}" for a in decode_int16(self.payload[:12], 100.0))
            return f"{self.name} [{values}] speed {self.payload[12]}"
        if self.cmd == SEND_COORDS and len(self.payload) >= 13:
            c = decode_int16(self.payload[:6], 10.0) + decode_int16(self.payload[6:12], 100.0)
            return f"{self.name} [{' '.join(f'{v:.2f}' for v in c)}] speed {self.payload[12]}"
        return f"{self.name} {self.payload.hex(' ')}".rstrip()


class FakeMyCobot:
    """A fake myCobot 280 peer in a background thread, on a pseudo-terminal or a loopback TCP port.

    Use as a context manager (``with FakeMyCobot("pty") as fake: MyCobot280(fake.device)``) or call
    :meth:`start` / :meth:`stop`. Everything received is in :attr:`commands` (thread-safe via :meth:`received`).
    """

    def __init__(self, transport: str = "pty", *, angles: Sequence[float] | None = None, silent: bool = False,
                 ack: bool = True, powered: bool = True, port: int = 0,
                 reply_payloads: dict[int, bytes] | None = None, on_command=None) -> None:
        """``transport`` is ``"pty"`` or ``"tcp"``; ``port`` is the TCP port (0: an ephemeral one).

        ``reply_payloads`` replaces the reply payload of given command codes (to feed clients malformed
        replies); ``on_command`` is called with each :class:`ReceivedCommand` (from the peer's thread).
        """
        if transport not in ("pty", "tcp"):
            raise ValueError(f"transport must be 'pty' or 'tcp', not {transport!r}")
        self.transport = transport
        self.angles: list[float] = [0.0] * 6 if angles is None else [float(a) for a in angles]
        if len(self.angles) != 6:
            raise ValueError(f"need 6 angles, got {len(self.angles)}")
        self.silent = silent
        self.ack = ack
        self.powered = powered
        self.reply_payloads = dict(reply_payloads or {})
        self.on_command = on_command
        self.commands: list[ReceivedCommand] = []
        self._requested_port = port
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._server: socket.socket | None = None
        self.device: str | None = None
        """Pseudo-terminal path to open as the serial port (pty transport)."""
        self.port: int | None = None
        """TCP port on 127.0.0.1 (tcp transport)."""

    # lifecycle

    def start(self) -> FakeMyCobot:
        """Open the pty or the listening socket and start answering in a daemon thread."""
        if self._thread is not None:
            raise RuntimeError("fake myCobot already started")
        self._stop.clear()
        if self.transport == "pty":
            self._master, self._slave = os.openpty()
            # raw: 0xFE/0xFA and friends must pass untouched, and nothing may be echoed back to the client
            tty.setraw(self._slave)
            self.device = os.ttyname(self._slave)
            target = self._serve_pty
        else:
            self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._server.bind(("127.0.0.1", self._requested_port))
            self._server.listen(1)
            self._server.settimeout(0.1)
            self.port = self._server.getsockname()[1]
            target = self._serve_tcp
        self._thread = threading.Thread(target=target, name=f"fake-mycobot-{self.transport}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and close the pty / socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        if self._server is not None:
            self._server.close()
            self._server = None

    def __enter__(self) -> FakeMyCobot:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def address(self) -> str:
        """Where clients connect: the pty path or ``127.0.0.1:PORT``."""
        return self.device if self.transport == "pty" else f"127.0.0.1:{self.port}"

    # what was received

    def received(self, cmd: int | None = None) -> list[ReceivedCommand]:
        """A copy of the received commands, optionally only those with code ``cmd``."""
        with self._lock:
            return [c for c in self.commands if cmd is None or c.cmd == cmd]

    def count(self, cmd: int) -> int:
        """How many frames with code ``cmd`` arrived."""
        return len(self.received(cmd))

    def clear(self) -> None:
        """Forget the received commands."""
        with self._lock:
            self.commands.clear()

    # protocol

    def coords(self) -> list[float]:
        """Current flange pose ``[x, y, z mm, rx, ry, rz deg]`` from our forward kinematics."""
        t = kinematics.forward(self.angles)
        return [float(v) for v in t[:3, 3]] + _rpy_deg(t[:3, :3])

    def handle(self, cmd: int, payload: bytes) -> bytes | None:
        """Record one command, update the state and return the reply frame (None: no reply)."""
        record = ReceivedCommand(cmd, payload, time.monotonic())
        with self._lock:
            self.commands.append(record)
            reply = None if self.silent else self._apply(cmd, payload)
        if self.on_command is not None:
            self.on_command(record)
        if reply is None:
            return None
        return encode_frame(cmd, self.reply_payloads.get(cmd, reply))

    def _apply(self, cmd: int, payload: bytes) -> bytes | None:
        if cmd == GET_ANGLES:
            return encode_int16(self.angles, 100.0)
        if cmd == GET_COORDS:
            c = self.coords()
            return encode_int16(c[:3], 10.0) + encode_int16(c[3:], 100.0)
        if cmd == IS_POWER_ON:
            return bytes([1 if self.powered else 0])
        if cmd == IS_CONTROLLER_CONNECTED:
            return bytes([1])
        if cmd == POWER_ON:
            self.powered = True
        elif cmd == POWER_OFF:
            self.powered = False
        elif cmd == SEND_ANGLES and len(payload) >= 13:
            self.angles = decode_int16(payload[:12], 100.0)
        elif cmd == SEND_ANGLE and len(payload) >= 4 and 1 <= payload[0] <= 6:
            self.angles[payload[0] - 1] = decode_int16(payload[1:3], 100.0)[0]
        elif cmd == SEND_COORDS and len(payload) >= 13:
            xyz = decode_int16(payload[:6], 10.0)
            rpy = decode_int16(payload[6:12], 100.0)
            try:
                self.angles = [float(a) for a in kinematics.inverse(xyz, _tool_axis(rpy), self.angles)]
            except ValueError:
                pass  # out of reach: the firmware stays where it is
        if cmd in _ACKED:
            return bytes([1]) if self.ack else None
        return None

    def _feed(self, buffer: bytearray, data: bytes, send) -> None:
        buffer.extend(data)
        for cmd, payload in parse_frames(buffer):
            reply = self.handle(cmd, payload)
            if reply is not None:
                send(reply)

    def _serve_pty(self) -> None:
        assert self._master is not None
        master = self._master
        buffer = bytearray()

        def send(reply: bytes) -> None:
            os.write(master, reply)

        while not self._stop.is_set():
            ready, _, _ = select.select([master], [], [], 0.05)
            if not ready:
                continue
            try:
                data = os.read(master, 4096)
            except OSError:
                # EIO while no client holds the slave open; we hold it ourselves, so this is rare
                time.sleep(0.05)
                continue
            self._feed(buffer, data, send)

    def _serve_tcp(self) -> None:
        assert self._server is not None
        while not self._stop.is_set():
            try:
                conn, _ = self._server.accept()
            except (TimeoutError, OSError):
                continue
            # like the arm's own server: one client at a time, served until it hangs up
            with conn:
                conn.settimeout(0.05)
                buffer = bytearray()
                while not self._stop.is_set():
                    try:
                        data = conn.recv(4096)
                    except TimeoutError:
                        continue
                    except OSError:
                        break
                    if not data:
                        break
                    try:
                        self._feed(buffer, data, conn.sendall)
                    except OSError:
                        break


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m lfdt.robot.fake_mycobot",
                                description="A fake myCobot 280 (serial frame protocol) for dry runs without an arm.")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty", action="store_true", help="serve on a pseudo-terminal; prints its device path")
    where.add_argument("--tcp", type=int, metavar="PORT", help="serve on 127.0.0.1:PORT (0: any free port)")
    p.add_argument("--angles", type=float, nargs=6, metavar="DEG", help="initial joint angles (default: zeros)")
    p.add_argument("--silent", action="store_true", help="never answer (to try timeouts)")
    p.add_argument("--quiet", action="store_true", help="do not print received commands")
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Serve a fake arm until Ctrl-C; prints ``device: PATH`` or ``port: N`` first."""
    args = _parse_args(argv)

    def show(record: ReceivedCommand) -> None:
        print(f"received: {record.describe()}", flush=True)

    # a shell without job control starts background commands with SIGINT ignored, and Python then never raises
    # KeyboardInterrupt: Ctrl-C (or `kill -INT`) must stop the fake however it was started
    signal.signal(signal.SIGINT, signal.default_int_handler)
    fake = FakeMyCobot("pty" if args.pty else "tcp", angles=args.angles, silent=args.silent,
                       port=args.tcp or 0, on_command=None if args.quiet else show)
    with fake:
        print(f"device: {fake.device}" if args.pty else f"port: {fake.port}", flush=True)
        try:
            while True:
                time.sleep(0.5)
        except KeyboardInterrupt:
            print("stopped", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
