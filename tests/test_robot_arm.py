"""lfdt.robot arm layer: pymycobot against a fake myCobot on a pty and on loopback TCP, the safety layer, the CLI.

No hardware: every MyCobotArm test runs pymycobot's own MyCobot280 / MyCobot280Socket code (framing, reply
parsing, retries) against lfdt.robot.fake_mycobot. Each connection costs pymycobot's 1.5 s constructor sleep.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pymycobot.common import ProtocolCode

from lfdt.rig.interrupt import stop_on_interrupt
from lfdt.robot import fake_mycobot as fm
from lfdt.robot.arm import (
    Arm,
    ArmNotResponding,
    MyCobotArm,
    SafeArm,
    SafetyError,
    SafetyLimits,
    SimArm,
    TrackingLost,
    check_command,
)
from lfdt.robot.cli import build_parser, main
from lfdt.robot.kinematics import position

ROOT = Path(__file__).resolve().parents[1]
START = [1.5, -2.25, 3.0, -4.0, 5.0, -6.5]


def _connect(fake: fm.FakeMyCobot, **kw) -> MyCobotArm:
    if fake.transport == "pty":
        return MyCobotArm.connect(port=fake.device, **kw)
    return MyCobotArm.connect(host="127.0.0.1", netport=fake.port, **kw)


def _where_args(fake: fm.FakeMyCobot) -> list[str]:
    if fake.transport == "pty":
        return ["--port", fake.device]
    return ["--host", "127.0.0.1", "--netport", str(fake.port)]


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cli(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lfdt.robot", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


# --- the fake's protocol --------------------------------------------------------------------------------------

def test_fake_uses_pymycobot_protocol_codes():
    for name in ("POWER_ON", "IS_POWER_ON", "GET_ANGLES", "SEND_ANGLES", "GET_COORDS", "SEND_COORDS", "STOP"):
        assert getattr(fm, name) == getattr(ProtocolCode, name), name
    assert (fm.GET_ANGLES, fm.SEND_ANGLES, fm.GET_COORDS, fm.SEND_COORDS, fm.POWER_ON, fm.IS_POWER_ON) == (
        0x20, 0x22, 0x23, 0x25, 0x10, 0x12)


def test_frame_encoding_and_resync():
    frame = fm.encode_frame(fm.SEND_ANGLES, fm.encode_int16([10.0, -20.5, 0, 0, 0, 0], 100.0) + bytes([50]))
    assert frame[:4] == bytes([0xFE, 0xFE, 15, 0x22]) and frame[-1] == 0xFA and len(frame) == 18
    assert frame[4:8] == bytes.fromhex("03e8f7fe")  # 1000, -2050 big-endian
    buf = bytearray(b"\x00\xfe\x12" + frame + fm.encode_frame(fm.GET_ANGLES)[:3])
    assert fm.parse_frames(buf) == [(0x22, frame[4:-1])]
    assert bytes(buf) == b"\xfe\xfe\x02"  # the incomplete GET_ANGLES stays for the next read
    buf.extend(b"\x20\xfa")
    assert fm.parse_frames(buf) == [(0x20, b"")] and buf == bytearray()


# --- MyCobotArm through pymycobot -------------------------------------------------------------------------------

@pytest.mark.parametrize("transport", ["pty", "tcp"])
def test_read_send_read_back_power_on(transport):
    with fm.FakeMyCobot(transport, angles=START, powered=False) as fake:
        arm = _connect(fake)
        try:
            assert isinstance(arm, Arm)
            assert arm.get_angles() == START
            target = [10.0, -20.0, 30.25, -40.0, 50.0, -60.0]
            arm.send_angles(target, 40)
            sent = fake.received(fm.SEND_ANGLES)
            assert len(sent) == 1 and sent[0].payload[12] == 40  # one frame: the fake acknowledged it
            assert fake.angles == target
            assert arm.get_angles() == target
            assert arm.is_power_on() is False
            arm.power_on()
            assert fake.powered and arm.is_power_on() is True
            # GET_COORDS through pymycobot's parser (mm x 10) matches our forward kinematics
            coords = arm.robot.get_coords()
            assert len(coords) == 6
            np.testing.assert_allclose(coords[:3], position(target), atol=0.15)
            arm.stop()
            assert fake.count(fm.STOP) == 1
        finally:
            arm.close()
    names = [c.name for c in fake.received()]
    assert names == ["GET_ANGLES", "SEND_ANGLES", "GET_ANGLES", "IS_POWER_ON", "POWER_ON", "IS_POWER_ON",
                     "GET_COORDS", "STOP"]


def test_malformed_replies_raise_not_garbage():
    # 8 bytes parse as 4 angles in pymycobot; 10 bytes make its parser raise struct.error
    with fm.FakeMyCobot("pty", reply_payloads={fm.GET_ANGLES: bytes(8)}) as fake:
        arm = _connect(fake)
        with pytest.raises(ArmNotResponding, match=r"GET_ANGLES.*0\.0, 0\.0, 0\.0, 0\.0\]"):
            arm.get_angles()
        fake.reply_payloads[fm.GET_ANGLES] = bytes(10)
        with pytest.raises(ArmNotResponding, match="garbled reply"):
            arm.get_angles()
        arm.close()


def test_unacknowledged_command_is_resent_three_times_then_fails():
    with fm.FakeMyCobot("pty", ack=False) as fake:
        arm = _connect(fake)
        with pytest.raises(ArmNotResponding, match=r"SEND_ANGLES: no reply .*/dev/"):
            arm.send_angles([1, 2, 3, 4, 5, 6], 20)
        assert fake.count(fm.SEND_ANGLES) == 3  # pymycobot re-sends when no reply comes
        lenient = MyCobotArm(arm.robot, arm.where, require_ack=False)
        fake.clear()
        lenient.send_angles([0, 0, 0, 0, 0, 0], 20)
        assert fake.count(fm.SEND_ANGLES) == 3
        arm.close()


def test_missing_serial_port_and_refused_host():
    with pytest.raises(ArmNotResponding, match="/dev/no-such-mycobot"):
        MyCobotArm.connect(port="/dev/no-such-mycobot")
    port = _free_tcp_port()
    with pytest.raises(ArmNotResponding, match=f"127.0.0.1:{port}"):
        MyCobotArm.connect(host="127.0.0.1", netport=port)
    with pytest.raises(ValueError):
        MyCobotArm.connect()


def test_tcp_connect_times_out_instead_of_hanging():
    # a listener whose backlog is full drops further SYNs: pymycobot's own connect would wait for minutes
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(0)
        port = server.getsockname()[1]
        fillers = [socket.socket() for _ in range(3)]
        try:
            for c in fillers:
                c.setblocking(False)
                c.connect_ex(("127.0.0.1", port))
            time.sleep(0.2)
            t0 = time.monotonic()
            with pytest.raises(ArmNotResponding, match=f"127.0.0.1:{port}: timed out"):
                MyCobotArm.connect(host="127.0.0.1", netport=port, timeout_s=1.0)
            assert 0.9 < time.monotonic() - t0 < 5.0
        finally:
            for c in fillers:
                c.close()


# --- CLI ----------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("transport", ["pty", "tcp"])
def test_cli_check_prints_angles(transport, capsys):
    with fm.FakeMyCobot(transport, angles=START) as fake:
        assert main(["check", *_where_args(fake)]) == 0
    out = capsys.readouterr().out
    assert out == "angles: 1.50 -2.25 3.00 -4.00 5.00 -6.50\n"
    assert [c.name for c in fake.received()] == ["GET_ANGLES"]


def test_cli_check_subprocess_on_pty():
    with fm.FakeMyCobot("pty", angles=START) as fake:
        r = _cli("check", "--port", fake.device)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == ["angles: 1.50 -2.25 3.00 -4.00 5.00 -6.50"]


def test_cli_move_sends_through_safe_arm(capsys):
    with fm.FakeMyCobot("pty", angles=START) as fake:
        target = ["10", "-20", "-30", "0", "15", "90"]
        assert main(["move", "--port", fake.device, "--angles", *target, "--speed", "25"]) == 0
        assert fake.angles == [10.0, -20.0, -30.0, 0.0, 15.0, 90.0]
        sent = fake.received(fm.SEND_ANGLES)
        assert len(sent) == 1 and sent[0].payload[12] == 25
    out = capsys.readouterr().out
    assert out.startswith("sent: angles 10.00 -20.00 -30.00 0.00 15.00 90.00 speed 25 to serial port /dev/")


@pytest.mark.parametrize("angles, speed, pattern", [
    (["0", "0", "171", "0", "0", "0"], "30", r"J3 = 171\.0 deg outside \[-150, 150\]"),
    (["-170", "0", "0", "0", "0", "0"], "30", r"J1 = -170\.0 deg outside \[-168, 168\]"),
    (["0", "0", "0", "0", "161", "0"], "30", r"J5 = 161\.0 deg outside \[-155, 160\]"),
    (["0", "-100", "-100", "0", "0", "0"], "30", r"z = -31\.0 mm below the workspace minimum 40\.0 mm"),
    (["0", "0", "0", "0", "0", "0"], "0", r"speed 0 outside 1\.\.100"),
    (["0", "0", "0", "0", "0", "0"], "101", r"speed 101 outside 1\.\.100"),
])
def test_cli_move_refusal_sends_nothing(angles, speed, pattern, capsys, monkeypatch):
    opened = []
    real_connect = MyCobotArm.connect
    monkeypatch.setattr(MyCobotArm, "connect", lambda **kw: opened.append(kw) or real_connect(**kw))
    with fm.FakeMyCobot("pty", angles=START) as fake:
        assert main(["move", "--port", fake.device, "--angles", *angles, "--speed", speed]) == 2
        time.sleep(0.1)
        assert fake.received() == [] and fake.angles == START
    assert opened == []  # validated before the port was even opened
    err = capsys.readouterr().err
    assert err.startswith("refused: ")
    assert re.search(pattern, err), err


def test_cli_move_refusal_subprocess_exit_code():
    with fm.FakeMyCobot("pty") as fake:
        r = _cli("move", "--port", fake.device, "--angles", "0", "0", "0", "146", "0", "0", "--speed", "10")
        assert fake.received() == []
    assert r.returncode == 2
    assert "J4 = 146.0 deg outside [-145, 145]" in r.stderr and r.stdout == ""


def test_cli_silent_peer_fails_fast_subprocess():
    with fm.FakeMyCobot("pty", silent=True) as fake:
        t0 = time.monotonic()
        r = _cli("check", "--port", fake.device)
        elapsed = time.monotonic() - t0
        assert fake.count(fm.GET_ANGLES) == 3  # it was asked, 3 times, and never answered
    print(f"silent pty check: {elapsed:.2f} s")
    assert r.returncode == 2
    assert elapsed < 10.0
    assert fake.device in r.stderr and "GET_ANGLES" in r.stderr and r.stdout == ""


def test_cli_silent_tcp_peer_fails_fast(capsys):
    with fm.FakeMyCobot("tcp", silent=True) as fake:
        t0 = time.monotonic()
        assert main(["check", "--host", "127.0.0.1", "--netport", str(fake.port)]) == 2
        elapsed = time.monotonic() - t0
    assert elapsed < 10.0
    assert f"127.0.0.1:{fake.port}" in capsys.readouterr().err


def test_cli_nothing_listening_on_tcp(capsys):
    port = _free_tcp_port()
    t0 = time.monotonic()
    assert main(["check", "--host", "127.0.0.1", "--netport", str(port)]) == 2
    assert time.monotonic() - t0 < 10.0
    err = capsys.readouterr().err
    assert f"127.0.0.1:{port}" in err and "refused" in err.lower()


def test_cli_missing_serial_port_subprocess():
    r = _cli("check", "--port", "/dev/no-such-mycobot")
    assert r.returncode == 2 and "/dev/no-such-mycobot" in r.stderr


@pytest.mark.parametrize("argv", [
    [],
    ["check"],
    ["check", "--port", "/dev/x", "--host", "h"],
    ["move", "--port", "/dev/x", "--angles", "1", "2", "3", "--speed", "10"],
    ["move", "--port", "/dev/x", "--angles", "1", "2", "3", "4", "5", "6", "--speed", "fast"],
])
def test_cli_bad_arguments_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    assert "error:" in capsys.readouterr().err


def test_parser_dispatches_one_function_per_subcommand():
    p = build_parser()
    a = p.parse_args(["check", "--host", "10.0.0.2"])
    b = p.parse_args(["move", "--port", "/dev/x", "--angles", "0", "0", "0", "0", "0", "0", "--speed", "5"])
    assert a.func.__name__ == "run_check" and a.netport == 9000 and a.port is None
    assert b.func.__name__ == "run_move" and b.angles == [0.0] * 6 and b.baudrate == 115200


def test_fake_entry_point_until_ctrl_c(capsys):
    proc = subprocess.Popen([sys.executable, "-m", "lfdt.robot.fake_mycobot", "--pty", "--angles", *map(str, START)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("device: /dev/")
        assert main(["check", "--port", line.split()[1]]) == 0
        assert capsys.readouterr().out == "angles: 1.50 -2.25 3.00 -4.00 5.00 -6.50\n"
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=10)
        assert proc.returncode == 0
        assert "received: GET_ANGLES" in out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


# --- SafeArm ------------------------------------------------------------------------------------------------------

def test_safe_arm_refusals_reach_nothing_on_the_wire():
    limits = SafetyLimits(workspace_min_mm=(0.0, -200.0, 60.0), workspace_max_mm=(300.0, 200.0, 300.0),
                          max_step_deg=10.0)
    home = [0.0, -30.0, -60.0, 0.0, 0.0, 0.0]  # flange at x 224, z 182
    with fm.FakeMyCobot("pty", angles=home) as fake:
        arm = SafeArm(_connect(fake), limits)
        try:
            with pytest.raises(SafetyError, match=r"J2 would change by \+15\.0 deg .* maximum step 10\.0 deg"):
                arm.send_angles([0.0, -15.0, -60.0, 0.0, 0.0, 0.0], 30)
            assert fake.count(fm.GET_ANGLES) == 1  # the first step check reads where the arm is
            with pytest.raises(SafetyError, match=r"z = 411\.1 mm above the workspace maximum 300\.0 mm"):
                arm.send_angles([0.0, 0.0, 0.0, 0.0, 0.0, 0.0], 30)
            with pytest.raises(SafetyError, match=r"x = -206\.0 mm below the workspace minimum 0\.0 mm"):
                arm.send_angles([168.0, -30.0, -60.0, 0.0, 0.0, 0.0], 30)
            with pytest.raises(SafetyError, match=r"J6 = 181\.0 deg outside \[-180, 180\]"):
                arm.send_angles([0.0, -30.0, -60.0, 0.0, 0.0, 181.0], 30)
            assert fake.count(fm.SEND_ANGLES) == 0
            arm.send_angles([5.0, -25.0, -55.0, 0.0, 0.0, 5.0], 30)
            assert fake.count(fm.SEND_ANGLES) == 1 and fake.angles == [5.0, -25.0, -55.0, 0.0, 0.0, 5.0]
            # now measured from the last command: +10 is fine, +10.5 is not
            arm.send_angles([5.0, -15.0, -55.0, 0.0, 0.0, 5.0], 30)
            with pytest.raises(SafetyError, match=r"J3 would change by -10\.5 deg"):
                arm.send_angles([5.0, -15.0, -65.5, 0.0, 0.0, 5.0], 30)
            assert fake.count(fm.SEND_ANGLES) == 2
        finally:
            arm.close()


def test_check_command_messages():
    with pytest.raises(SafetyError, match="J3 = 171.0 deg outside \\[-150, 150\\]"):
        check_command([0, 0, 171, 0, 0, 0], 50)
    with pytest.raises(SafetyError, match="need 6 joint angles, got 5"):
        check_command([0, 0, 0, 0, 0], 50)
    with pytest.raises(SafetyError, match="J2 = nan"):
        check_command([0, float("nan"), 0, 0, 0, 0], 50)
    with pytest.raises(SafetyError, match="speed 50.0"):
        check_command([0] * 6, 50.0)
    assert check_command([0, -30, -60, 0, 0, 0], np.int64(50)) == [0.0, -30.0, -60.0, 0.0, 0.0, 0.0]


def test_tracking_lost_stops_after_max_frames():
    sim = SimArm(max_step_deg=5.0)
    arm = SafeArm(sim, SafetyLimits(max_lost_frames=3, max_step_deg=None))
    arm.send_angles([10, 0, -20, 0, 0, 0], 50)
    for n in range(4):
        arm.tracking_lost(n)
    assert sim.stop_count == 0 and sim.target is not None
    with pytest.raises(TrackingLost, match="4 frames"):
        arm.tracking_lost(4)
    assert sim.stop_count == 1 and sim.target is None
    held = sim.get_angles()
    sim.step()
    assert sim.get_angles() == held  # stopped: no further motion toward the old target


def test_tracking_lost_sends_stop_frame():
    with fm.FakeMyCobot("tcp") as fake:
        arm = SafeArm(_connect(fake), SafetyLimits(max_lost_frames=2))
        try:
            arm.tracking_lost(2)
            assert fake.count(fm.STOP) == 0
            with pytest.raises(TrackingLost):
                arm.tracking_lost(3)
            assert fake.count(fm.STOP) == 1
        finally:
            arm.close()


# --- SimArm, Ctrl-C -------------------------------------------------------------------------------------------

def test_sim_arm_follows_with_a_lag():
    sim = SimArm([0, 0, 0, 0, 0, 0], max_step_deg=5.0)
    sim.send_angles([12, -3, 0, 0, 0, -20], 50)
    assert sim.get_angles() == [5, -3, 0, 0, 0, -5]
    sim.send_angles([12, -3, 0, 0, 0, -20], 50)
    assert sim.get_angles() == [10, -3, 0, 0, 0, -10]
    sim.step()
    sim.step()
    assert sim.get_angles() == [12, -3, 0, 0, 0, -20]
    sim.step()
    assert sim.get_angles() == [12, -3, 0, 0, 0, -20]  # no overshoot
    assert len(sim.commands) == 2 and sim.commands[0][1] == 50
    assert isinstance(sim, Arm)


def test_ctrl_c_stops_and_closes_then_reraises():
    before = signal.getsignal(signal.SIGINT)
    sim = SimArm()
    with pytest.raises(KeyboardInterrupt):
        with stop_on_interrupt(SafeArm(sim, SafetyLimits(max_step_deg=None))) as arm:
            arm.send_angles([10, 0, -20, 0, 0, 0], 50)
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)
            pytest.fail("SIGINT did not interrupt")
    assert sim.stop_count == 1 and sim.closed
    assert signal.getsignal(signal.SIGINT) is before


def test_ctrl_c_during_stop_is_ignored():
    class Impatient(SimArm):
        def stop(self) -> None:
            os.kill(os.getpid(), signal.SIGINT)  # the user presses Ctrl-C again while stopping
            time.sleep(0.05)
            super().stop()

    sim = Impatient()
    with pytest.raises(KeyboardInterrupt):
        with stop_on_interrupt(sim):
            raise KeyboardInterrupt
    assert sim.stop_count == 1 and sim.closed


def test_no_interrupt_leaves_arm_open():
    sim = SimArm()
    with stop_on_interrupt(sim):
        sim.send_angles([1, 0, 0, 0, 0, 0], 10)
    assert sim.stop_count == 0 and not sim.closed
