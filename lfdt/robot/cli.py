"""Command line for the real arms: ``python -m lfdt.robot COMMAND ...``.

Each subcommand has an ``add_<name>_parser`` function that registers it and a ``run_<name>(args) -> int`` function
bound with ``set_defaults(func=...)``. Exit codes: 0 done; 2 bad arguments (argparse), a refused command
(SafetyError) or an arm that does not answer (ArmNotResponding); anything else propagates with a traceback.

Try it without hardware: ``python -m lfdt.robot.fake_mycobot --pty`` prints a device path to pass as ``--port``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from lfdt.robot.arm import (
    ArmNotResponding,
    MyCobotArm,
    SafeArm,
    SafetyError,
    SafetyLimits,
    check_command,
    stop_on_interrupt,
)

EXIT_FAILED = 2
"""A refused command or an arm that does not answer (the same code argparse uses for bad arguments)."""

MOVE_LIMITS = SafetyLimits(max_step_deg=None)
"""``move``: joint limits, speed and the default workspace box (flange 40 mm or more above the mounting surface,
within 350 mm sideways, 500 mm up), no step limit: a single move from wherever the arm is, which the firmware
interpolates itself, has no previous command to compare with; and validating without reading the arm lets a
refusal happen before anything is opened."""


def _format_angles(angles: Sequence[float]) -> str:
    return " ".join(f"{a:.2f}" for a in angles)


def add_connection_arguments(parser: argparse.ArgumentParser) -> None:
    """``--port`` (serial) or ``--host``/``--netport`` (TCP), ``--baudrate`` and ``--connect-timeout``."""
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--port", help="serial port of the arm, e.g. /dev/ttyUSB0 or /dev/ttyACM0")
    where.add_argument("--host", help="IP address of the arm's TCP server (myCobot 280 Pi / JN)")
    parser.add_argument("--netport", type=int, default=9000, help="TCP port of the arm's server (default: 9000)")
    parser.add_argument("--baudrate", type=int, default=115200, help="serial baud rate (default: 115200)")
    parser.add_argument("--connect-timeout", type=float, default=3.0, metavar="S",
                        help="seconds to wait for the TCP connection (default: 3)")


def connect(args: argparse.Namespace) -> MyCobotArm:
    """Open the arm named by the connection arguments (raises ArmNotResponding)."""
    return MyCobotArm.connect(port=args.port, host=args.host, netport=args.netport, baudrate=args.baudrate,
                              timeout_s=args.connect_timeout)


def add_check_parser(subparsers) -> None:
    """Register ``check``."""
    p = subparsers.add_parser("check", help="connect to one arm and print its joint angles",
                              description="Connect to one arm and print its joint angles (degrees) as one line "
                                          "'angles: a1 ... a6'. Exit 2 when it does not answer.")
    add_connection_arguments(p)
    p.set_defaults(func=run_check)


def run_check(args: argparse.Namespace) -> int:
    """Print ``angles: a1 a2 a3 a4 a5 a6``; ArmNotResponding when nothing answers."""
    arm = connect(args)
    try:
        angles = arm.get_angles()
    finally:
        arm.close()
    print(f"angles: {_format_angles(angles)}")
    return 0


def add_move_parser(subparsers) -> None:
    """Register ``move``."""
    p = subparsers.add_parser("move", help="move one arm to joint angles (safety-checked)",
                              description="Send one joint target to one arm through the safety layer: joint "
                                          "limits, speed 1..100 and a loose flange workspace (z >= 40 mm, |x|, "
                                          "|y| <= 350 mm, z <= 500 mm) are checked before the port is opened; "
                                          "no per-step limit. Returns once the target is sent, without waiting "
                                          "for the arm to arrive. Ctrl-C stops the arm.")
    add_connection_arguments(p)
    p.add_argument("--angles", type=float, nargs=6, required=True, metavar=("J1", "J2", "J3", "J4", "J5", "J6"),
                   help="target joint angles, degrees")
    p.add_argument("--speed", type=int, required=True, help="speed 1..100")
    p.set_defaults(func=run_move)


def run_move(args: argparse.Namespace) -> int:
    """Validate, connect, send; a refusal raises SafetyError before anything is opened."""
    angles = check_command(args.angles, args.speed, MOVE_LIMITS)
    arm = SafeArm(connect(args), MOVE_LIMITS)
    try:
        with stop_on_interrupt(arm):
            arm.send_angles(angles, args.speed)
    finally:
        arm.close()
    print(f"sent: angles {_format_angles(angles)} speed {args.speed} to {arm.arm.where}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m lfdt.robot`` parser; add subcommands with an ``add_<name>_parser(subparsers)`` function."""
    parser = argparse.ArgumentParser(prog="python -m lfdt.robot",
                                     description="Talk to the myCobot 280 arms (see lfdt-spec §5).")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_check_parser(subparsers)
    add_move_parser(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one subcommand; returns the exit code (argparse exits 2 itself on bad arguments)."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except SafetyError as e:
        print(f"refused: {e}; nothing was sent", file=sys.stderr)
        return EXIT_FAILED
    except ArmNotResponding as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_FAILED
