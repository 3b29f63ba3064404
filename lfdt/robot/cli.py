"""Command line for the real arms: ``python -m lfdt.robot COMMAND ...``.

Each subcommand has an ``add_<name>_parser`` function that registers it and a ``run_<name>(args) -> int`` function
bound with ``set_defaults(func=...)``. Exit codes: 0 done; 2 bad arguments (argparse), a refused command
(SafetyError), an arm that does not answer (ArmNotResponding), or a file or folder given on the command line or in
the rig config that cannot be used (checked by :mod:`lfdt.inputs` before anything moves or is written; a full disk
or a refused write later on ends the same way, naming the file); 130 Ctrl-C. Each ends with one line on stderr;
anything else propagates with a traceback.

Try it without hardware: ``python -m lfdt.robot.fake_mycobot --pty`` prints a device path to pass as ``--port``.

The data and deployment commands (``calibrate``, ``write-rig-config``, ``record-random``, ``record-demos``, ``deploy``)
work on a whole rig (:mod:`lfdt.rig.base`: both arms and the camera, described by a JSON file) or, with ``--sim``,
on the MuJoCo twin. They stop the arms on Ctrl-C (exit 130) and on any error; recordings keep only finished
episodes (each written atomically when it ends), so an interrupted or killed recording leaves complete files only.
Exit code 2 also covers a refused target, lost tracking and an unusable rig config.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from lfdt import inputs, twin
from lfdt.errors import INTERRUPTED, StageError
from lfdt.inputs import nonnegative_float, positive_float, positive_int, tcp_port
from lfdt.rig.interrupt import stop_on_interrupt
from lfdt.robot.arm import (
    ArmNotResponding,
    MyCobotArm,
    SafeArm,
    SafetyError,
    SafetyLimits,
    TrackingLost,
    check_command,
)
from lfdt.tasks import registry

EXIT_FAILED = 2
"""A refused command or an arm that does not answer (the same code argparse uses for bad arguments)."""
EXIT_INTERRUPTED = INTERRUPTED
"""Ctrl-C (128 + SIGINT), as shells report it."""
TASKS = registry.PLANAR


def episode_count(text: str) -> int:
    """argparse type: a count of episodes, attempts or trials, each of which has its own start state among the
    :data:`lfdt.seeding.MAX_EPISODES` of a seed (:func:`positive_int` at most that many)."""
    from lfdt.seeding import MAX_EPISODES

    value = positive_int(text)
    if value > MAX_EPISODES:
        raise argparse.ArgumentTypeError(f"{value} is more than the {MAX_EPISODES} start states a seed has")
    return value


MAX_EPISODE_STEPS = 100_000
"""The longest recorded episode, in control steps: 2.8 hours at the twin's 0.1 s control period. A recording keeps
an episode's rows in memory until the episode ends (about 3 KB a step on the twin, measured), so a mistyped count
would fill the memory over hours before anything is written; longer motion is more episodes."""


def episode_steps(text: str) -> int:
    """argparse type: control steps of one recorded episode (:func:`positive_int` at most
    :data:`MAX_EPISODE_STEPS`)."""
    value = positive_int(text)
    if value > MAX_EPISODE_STEPS:
        raise argparse.ArgumentTypeError(f"{value} is more than the {MAX_EPISODE_STEPS} control steps an episode "
                                         f"may have (its rows are held in memory until it ends); record longer "
                                         f"motion as more episodes")
    return value


def _check_room(first: int, count: int, option: str, where: str) -> None:
    """Episodes ``first`` .. ``first + count - 1`` each have a start state (:data:`lfdt.seeding.MAX_EPISODES` per
    seed); an InputError naming ``option`` and what ``where`` holds already otherwise, before anything moves."""
    from lfdt.errors import InputError
    from lfdt.seeding import MAX_EPISODES

    if first + count > MAX_EPISODES:
        raise InputError(f"{option} {count}: {where} holds {first} already, and a seed has {MAX_EPISODES} start "
                         f"states; at most {max(MAX_EPISODES - first, 0)} more")


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
    parser.add_argument("--netport", type=tcp_port, default=9000, help="TCP port of the arm's server (default: 9000)")
    parser.add_argument("--baudrate", type=positive_int, default=115200, help="serial baud rate (default: 115200)")
    parser.add_argument("--connect-timeout", type=positive_float, default=3.0, metavar="S",
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


# ---------------------------------------------------------------------------------------------------------------
# calibration and rig configuration


def _camera_source(text: str) -> int | str:
    """A camera index ("0") or a video path."""
    return int(text) if text.isdigit() else text


def add_calibrate_parser(subparsers) -> None:
    """Register ``calibrate``."""
    p = subparsers.add_parser("calibrate", help="calibrate the camera from views of a chessboard (or ChArUco board)",
                              description="Grab views of a printed board from a camera or a video, calibrate the "
                                          "intrinsics and distortion, save them as JSON and print the RMS "
                                          "reprojection error. Move the board around (tilted, near the corners) "
                                          "while frames are grabbed. Exit 2 when too few views show the board.")
    p.add_argument("--camera", required=True, metavar="SRC", help="camera index (e.g. 0) or a video file")
    p.add_argument("--pattern", type=int, nargs=2, required=True, metavar=("COLS", "ROWS"),
                   help="chessboard: inner corners per row and column; with --charuco: squares")
    p.add_argument("--square", type=positive_float, required=True, metavar="M", help="square edge, metres")
    p.add_argument("--charuco", action="store_true", help="the board is a ChArUco board (AprilTag 36h11 markers)")
    p.add_argument("--marker", type=positive_float, metavar="M", help="ChArUco marker edge, metres (with --charuco)")
    p.add_argument("--frames", type=positive_int, default=20, metavar="N", help="views to grab (default: 20)")
    p.add_argument("--every", type=nonnegative_float, default=0.5, metavar="S",
                   help="seconds between grabbed views (camera time, or video time for a file; default: 0.5)")
    p.add_argument("--min-views", type=positive_int, default=6, metavar="N",
                   help="fewest views with the board needed to calibrate (default: 6)")
    p.add_argument("--out", required=True, type=Path, metavar="CALIB_JSON", help="calibration JSON to write")
    p.set_defaults(func=run_calibrate)


def _check_board(args: argparse.Namespace) -> None:
    """The board and the counts make a calibration possible, before any frame is grabbed (OpenCV would refuse them
    after the operator moved the board around, or fail inside its ChArUco constructor); an InputError names the
    option."""
    from lfdt.errors import InputError

    fewest = 2 if args.charuco else 3  # squares of a ChArUco board; a chessboard's inner corners (OpenCV: > 2)
    if min(args.pattern) < fewest:
        board, what = ("a ChArUco board", "squares") if args.charuco else ("a chessboard", "inner corners")
        raise InputError(f"--pattern {args.pattern[0]} {args.pattern[1]}: {board} needs at least {fewest} {what} "
                         "per row and column")
    if args.charuco and args.marker >= args.square:
        raise InputError(f"--marker {args.marker:g}: the marker must be smaller than its square (--square "
                         f"{args.square:g})")
    if args.min_views > args.frames:
        raise InputError(f"--min-views {args.min_views}: more views than --frames {args.frames} grabs")


def run_calibrate(args: argparse.Namespace) -> int:
    """Grab, calibrate, save; exit 2 with a message when the board was seen in fewer than --min-views views."""
    from lfdt.robot import calibration
    from lfdt.robot.tracker import open_capture

    if args.charuco and args.marker is None:
        print("error: --charuco needs --marker (marker edge in metres)", file=sys.stderr)
        return EXIT_FAILED
    _check_board(args)
    source = _camera_source(args.camera)
    if isinstance(source, int):
        inputs.camera_device(source, "--camera")
    else:
        inputs.readable_file(source, "--camera", "a video file, or a camera index such as 0")
    inputs.writable_file(args.out, "--out", "a path for the calibration JSON")
    try:
        cap = open_capture(source)
    except (FileNotFoundError, RuntimeError) as e:
        print(f"error: cannot open camera {args.camera}: {e}", file=sys.stderr)
        return EXIT_FAILED
    print(f"grabbing up to {args.frames} views of the board, {args.every:g} s apart; move the board around",
          file=sys.stderr)
    try:
        frames = calibration.collect_frames(
            cap, args.frames, args.every, pattern=None if args.charuco else tuple(args.pattern),
            time_base="wall" if isinstance(source, int) else "video")
    finally:
        cap.release()
    board = None
    try:
        if args.charuco:
            board = calibration.make_charuco_board(tuple(args.pattern), args.square, args.marker)
            calib = calibration.calibrate_charuco(frames, board)
        else:
            calib = calibration.calibrate_chessboard(frames, tuple(args.pattern), args.square)
    except ValueError as e:  # no frames, or fewer than 3 usable views
        calib, reason = None, str(e)
    if calib is None or calib.n_views < args.min_views:
        seen = 0 if calib is None else calib.n_views
        what = "ChArUco board" if board is not None else f"{args.pattern[0]}x{args.pattern[1]} chessboard"
        print(f"error: the {what} was usable in {seen} views ({len(frames)} frames grabbed), {args.min_views} "
              f"needed" + (f" ({reason})" if calib is None else "") + "; nothing was saved", file=sys.stderr)
        return EXIT_FAILED
    calibration.save_calibration(args.out, calib)
    k = calib.camera_matrix
    print(f"calibrated from {calib.n_views} views: RMS reprojection error {calib.rms_px:.3f} px; "
          f"fx {k[0, 0]:.1f} fy {k[1, 1]:.1f} cx {k[0, 2]:.1f} cy {k[1, 2]:.1f}; saved {args.out}")
    return 0


def add_write_rig_config_parser(subparsers) -> None:
    """Register ``write-rig-config``."""
    p = subparsers.add_parser("write-rig-config", help="write an example rig configuration to edit",
                              description="Write a documented example rig configuration (both arms, the camera, "
                                          "the control loop) as JSON; edit ports, base poses and tag poses to "
                                          "match your setup.")
    p.add_argument("--out", required=True, type=Path, metavar="RIG_JSON", help="JSON file to write")
    p.add_argument("--task", choices=TASKS, default="block_push", help="task of the example (default: block_push)")
    p.add_argument("--force", action="store_true", help="overwrite an existing file")
    p.set_defaults(func=run_write_rig_config)


def run_write_rig_config(args: argparse.Namespace) -> int:
    """Write the example; exit 2 when the file exists and --force is not given."""
    from lfdt.robot.rig_config import write_rig_config

    inputs.writable_file(args.out, "--out", "a path for the rig JSON")
    try:
        path = write_rig_config(args.out, args.task, overwrite=args.force)
    except FileExistsError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_FAILED
    print(f"wrote {path}")
    return 0


# ---------------------------------------------------------------------------------------------------------------
# recording and deployment on a rig


def add_rig_arguments(parser: argparse.ArgumentParser, task_required: bool = False) -> None:
    """``--rig``, ``--sim``, ``--task``, ``--step-delay``, ``--yes`` shared by the rig commands."""
    parser.add_argument("--rig", type=Path, metavar="RIG_JSON", help="rig configuration (write-rig-config); "
                        "required unless --sim")
    parser.add_argument("--sim", action="store_true", help="run on the MuJoCo twin instead of the robots")
    parser.add_argument("--task", choices=TASKS, required=task_required,
                        help="the task (must match the rig's)" if task_required else
                        "task of the twin (with --sim and no --rig); otherwise the rig's")
    parser.add_argument("--step-delay", type=nonnegative_float, default=0.0, metavar="S",
                        help="--sim: sleep S seconds per step, to pace a dry run like the robots (default: 0)")


def _rig_task(args: argparse.Namespace):
    """The task and the rig config (None with --sim and no --rig); exit-2 errors as RigConfigError."""
    from lfdt.robot.rig_config import RigConfigError, check_camera, load_rig_config

    config = None
    if args.rig is not None:
        config = load_rig_config(args.rig)
    elif not args.sim:
        raise RigConfigError("--rig RIG_JSON is required (or --sim for the twin)")
    if config is not None and args.task is not None and args.task != config.task:
        raise RigConfigError(f"--task {args.task} but {args.rig} is set up for {config.task}")
    task = args.task or (config.task if config is not None else None)
    if task is None:
        raise RigConfigError("--sim without --rig needs --task")
    if config is not None and not args.sim:
        check_camera(config, f"--rig {args.rig}")  # the calibration and the camera, before any arm moves
    return task, config


def _make_rig(args: argparse.Namespace, task: str, config, domain: str, human: str, seed: int,
              max_steps: int | None = None):
    from lfdt.rig.sim import SimRig
    from lfdt.robot.real_rig import RealRig

    if args.sim:
        return SimRig(task, domain, seed=seed, human=human, step_delay=args.step_delay, max_steps=max_steps)
    return RealRig(config, domain)


def _ask_yes_no(question: str) -> bool:
    """Ask the operator on stdin until they answer y or n."""
    while True:
        answer = input(f"{question} [y/n] ").strip().lower()
        if answer in ("y", "yes"):
            return True
        if answer in ("n", "no"):
            return False


def _wait_for_operator(rig, prompt: str, skip: bool) -> None:
    """Real robots: let the operator set the scene before an episode (unless --yes)."""
    from lfdt.robot.real_rig import RealRig

    if isinstance(rig, RealRig) and not skip:
        input(f"{prompt}; press Enter to start ")


def _episodes_in(directory: Path) -> int:
    from lfdt.rig.recording import EPISODE_GLOB

    return len(list(Path(directory).glob(EPISODE_GLOB)))


def _metadata(args: argparse.Namespace, config, **extra) -> dict:
    meta = {"source": "twin" if args.sim else "robots", **extra}
    if config is not None and not args.sim:
        meta["rig"] = config.model_dump(mode="json", by_alias=True)
    return meta


def _progress(total: int, unit: str, desc: str):
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=desc, file=sys.stderr, dynamic_ncols=True)


def _record_loop(rig, rec, out: Path, episodes: int, unit: str, run_episode) -> int:
    """Run ``run_episode()`` (True: an episode was kept) until ``episodes`` are kept; Ctrl-C and errors leave the
    finished episodes and drop the one in progress."""
    from lfdt.rig.base import running

    bar = _progress(episodes, unit, out.name)
    try:
        with running(rig), bar:
            while bar.n < episodes:
                if run_episode():
                    bar.update(1)
    except KeyboardInterrupt:
        rec.abort()
        print(f"interrupted: arms stopped; {_episodes_in(out)} finished episodes in {out}, the episode in "
              f"progress was dropped", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BaseException as e:
        rec.abort()
        # main prints the error and this note on one line
        e.add_note(f"stopped: {_episodes_in(out)} finished episodes in {out}, the episode in progress was dropped")
        raise
    return 0


def add_record_random_parser(subparsers) -> None:
    """Register ``record-random``."""
    p = subparsers.add_parser("record-random", help="record random motion of the robots (dynamics data)",
                              description="Random motion in one domain: each robot's target is a random offset "
                                          "of up to --reach from its end, held for 1..--hold-max steps "
                                          "(recording.record_random_episode); the person moves freely (robots) "
                                          "or randomly "
                                          "(--sim). One Parquet file per episode under --out (twin_schema "
                                          "'random'); the human slot's action is its measured motion (robots) "
                                          "or its random target (--sim). Episodes already in --out are kept "
                                          "and numbering continues.")
    add_rig_arguments(p)
    p.add_argument("--domain", required=True, choices=("Y", "R1H", "HR2"))
    p.add_argument("--episodes", type=episode_count, required=True, metavar="N", help="episodes to record")
    p.add_argument("--steps", type=episode_steps, required=True, metavar="T", help="control steps per episode")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="recording directory")
    p.add_argument("--seed", type=int, default=0, choices=range(10), metavar="S", help="seed 0..9 (default: 0)")
    p.add_argument("--reach", type=positive_float, default=0.008, metavar="M",
                   help="largest random offset per axis, metres (default: 0.008)")
    p.add_argument("--hold-max", type=positive_int, default=3, metavar="K",
                   help="hold a target 1..K steps (default: 3)")
    p.add_argument("--human", choices=("random", "scripted"), default="random",
                   help="--sim in R1H/HR2: how the twin's person moves (default: random)")
    p.add_argument("--yes", action="store_true", help="robots: start each episode without waiting for Enter")
    p.set_defaults(func=run_record_random)


def run_record_random(args: argparse.Namespace) -> int:
    """Record ``--episodes`` episodes of ``--steps`` random steps; returns 0, or 130 on Ctrl-C."""
    import numpy as np

    from lfdt.rig.recording import EpisodeRecorder, record_random_episode
    from lfdt.seeding import episode_seed
    from lfdt.twin.common import twin_schema

    task, config = _rig_task(args)
    inputs.output_folder(args.out, "--out", "a folder for the recording (one Parquet file per episode)")
    rig = _make_rig(args, task, config, args.domain, args.human, args.seed)
    meta = _metadata(args, config, seed=args.seed, steps=args.steps, reach=args.reach, hold_max=args.hold_max)
    rec = EpisodeRecorder(args.out, twin_schema(task, args.domain, "random", meta), rig.control_dt)
    _check_room(rec.next_index(), args.episodes, "--episodes", f"--out {args.out}")

    def episode() -> bool:
        index = rec.start()
        s = episode_seed("random", args.seed, args.domain, index)
        rig.reset(seed=s)
        _wait_for_operator(rig, f"episode {index}: robots at their start poses", args.yes)
        record_random_episode(rig, rec, np.random.default_rng(s), args.steps, args.reach, args.hold_max)
        return True

    code = _record_loop(rig, rec, args.out, args.episodes, "episode", episode)
    if code == 0:
        print(f"recorded {args.episodes} episodes of {args.steps} steps in {args.out} "
              f"({_episodes_in(args.out)} in all)")
    return code


def add_record_demos_parser(subparsers) -> None:
    """Register ``record-demos``."""
    p = subparsers.add_parser("record-demos", help="record demonstrations with one robot and a person",
                              description="Demonstrations in domain X: the pairing's robot replays the programmed "
                                          "motion (lfdt.tasks.demonstrators.ProgrammedMotion) while the person's hand "
                                          "is tracked; "
                                          "after each episode the operator says whether it succeeded (--sim: "
                                          "the twin's success flag; --yes: keep every episode). Successful "
                                          "episodes are kept (one Parquet file each, twin_schema 'demos'), "
                                          "the others dropped.")
    add_rig_arguments(p)
    p.add_argument("--pairing", required=True, choices=("R1H", "HR2"))
    p.add_argument("--episodes", type=episode_count, required=True, metavar="N",
                   help="successful demonstrations to keep")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="recording directory")
    p.add_argument("--steps", type=episode_steps, default=40, metavar="T",
                   help="longest episode, control steps (default: 40, the twin's episode)")
    p.add_argument("--max-attempts", type=episode_count, metavar="M", help="give up after M attempts (default: 5 N)")
    p.add_argument("--seed", type=int, default=0, choices=range(10), metavar="S", help="seed 0..9 (default: 0)")
    p.add_argument("--yes", action="store_true", help="robots: keep every episode, do not ask or wait for Enter")
    p.set_defaults(func=run_record_demos)


def run_record_demos(args: argparse.Namespace) -> int:
    """Record until ``--episodes`` successful demonstrations are kept; exit 2 after --max-attempts."""
    from lfdt import layout
    from lfdt.rig.recording import EpisodeRecorder, record_demo_episode
    from lfdt.seeding import episode_seed
    from lfdt.tasks.demonstrators import ProgrammedMotion
    from lfdt.twin.common import twin_schema

    task, config = _rig_task(args)
    inputs.output_folder(args.out, "--out", "a folder for the recording (one Parquet file per episode)")
    rig = _make_rig(args, task, config, args.pairing, "scripted", args.seed, max_steps=args.steps)
    robot = layout.robot_arm(args.pairing)
    slot = rig.slots.index(robot)
    max_attempts = 5 * args.episodes if args.max_attempts is None else args.max_attempts
    meta = _metadata(args, config, seed=args.seed, steps=args.steps)
    rec = EpisodeRecorder(args.out, twin_schema(task, args.pairing, "demos", meta), rig.control_dt)
    goal_line = config.goal_line_m if config is not None and not args.sim else None
    attempts = {"n": 0, "first": rec.next_index()}
    _check_room(attempts["first"], max_attempts, "--max-attempts" if args.max_attempts else "--episodes (5 N attempts)",
                f"--out {args.out}")

    def episode() -> bool:
        if attempts["n"] >= max_attempts:
            raise _GiveUp(f"{_episodes_in(args.out)} successful demonstrations after {attempts['n']} attempts "
                          f"(--max-attempts {max_attempts})")
        s = episode_seed("demos", args.seed, args.pairing, attempts["first"] + attempts["n"])
        attempts["n"] += 1
        rec.start()
        rig.reset(seed=s)
        _wait_for_operator(rig, f"attempt {attempts['n']}: robot at its start pose, set the scene", args.yes)
        obs = rig.observe()  # the scene as the operator set it: the program is made from it, once per take
        program = ProgrammedMotion(task, slot, obs, rig.control_dt, goal_line=goal_line)
        ok, _ = record_demo_episode(rig, rec, program, robot, args.steps)
        if ok is None:
            ok = True if args.yes else _ask_yes_no(f"attempt {attempts['n']}: did the demonstration succeed?")
        if ok:
            rec.finish()
        else:
            rec.abort()
        return ok

    try:
        code = _record_loop(rig, rec, args.out, args.episodes, "demo", episode)
    except _GiveUp as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_FAILED
    if code == 0:
        print(f"kept {args.episodes} successful demonstrations of {attempts['n']} attempts in {args.out}")
    return code


class _GiveUp(RuntimeError):
    """Too many failed attempts."""


def add_deploy_parser(subparsers) -> None:
    """Register ``deploy``."""
    p = subparsers.add_parser("deploy", help="run a trained policy on both robots and log the outcomes",
                              description="Trials of a trained twin policy (lfdt.twin.evaluate.load_policy) in "
                                          "domain Y: "
                                          "up to --steps control steps per trial, then the operator says whether "
                                          "the task succeeded (--sim: the twin's success flag, from the twin "
                                          "evaluation's start states). Each outcome is appended to --log as a "
                                          "row 'trial,success' as soon as it is known; trial numbers continue "
                                          "after those already in the log. The DVC stage twin_evaluate reads "
                                          "real_dir/TASK/deploy_METHOD.csv with twin.backend: real.")
    add_rig_arguments(p, task_required=True)
    p.add_argument("--method", required=True, choices=twin.TWIN_METHODS)
    p.add_argument("--models", required=True, metavar="DIR|URI",
                   help="trained models of one seed, e.g. models/twin/TASK/s0, or a registered policy, e.g. "
                        "models:/TASK.METHOD@seed3 (reports/models.csv lists them)")
    p.add_argument("--trials", type=episode_count, required=True, metavar="N", help="trials to run")
    p.add_argument("--log", required=True, type=Path, metavar="CSV",
                   help="outcome log, e.g. data/real/TASK/deploy_METHOD.csv")
    p.add_argument("--steps", type=positive_int, default=40, metavar="T",
                   help="longest trial, control steps (default: 40, the twin's episode)")
    p.set_defaults(func=run_deploy)


def run_deploy(args: argparse.Namespace) -> int:
    """Run ``--trials`` trials and append their outcomes; returns 0, or 130 on Ctrl-C. Before each trial the log is
    checked to take its outcome (:func:`lfdt.rig.deploy_log.check_appendable`): a trial whose outcome could not be
    kept is not run."""
    from lfdt import policy_models
    from lfdt.evaluation import evaluation_seeds
    from lfdt.nets import ModelFileError
    from lfdt.rig import deploy_log
    from lfdt.rig.base import running
    from lfdt.twin.evaluate import load_policy

    task, config = _rig_task(args)
    done = deploy_log.check_appendable(args.log, "--log")
    _check_room(done, args.trials, "--trials", f"--log {args.log}")
    if policy_models.is_uri(args.models):
        from mlflow.exceptions import MlflowException

        try:
            policy = policy_models.policy_from_uri(args.models, task, args.method)
        except (MlflowException, ValueError) as e:
            print(f"error: --models {args.models}: {e}", file=sys.stderr)
            return EXIT_FAILED
    elif not (Path(args.models) / args.method).is_dir():
        print(f"error: --models {args.models}: no trained {args.method} policy in {Path(args.models) / args.method} "
              f"(the twin_train stage writes models/twin/TASK/s<seed>/; with twin.backend: real after recording)",
              file=sys.stderr)
        return EXIT_FAILED
    else:
        try:
            policy = load_policy(task, args.method, args.models)
        except ModelFileError as e:  # a missing or damaged sidecar or weights file
            print(f"error: --models {args.models}: {e}", file=sys.stderr)
            return EXIT_FAILED
    rig = _make_rig(args, task, config, "Y", "scripted", 0, max_steps=args.steps)
    seeds = evaluation_seeds(done + args.trials)  # the twin evaluation's start states, trial by trial
    successes = 0
    bar = _progress(args.trials, "trial", f"{task} {args.method}")
    try:
        with running(rig), bar:
            for trial in range(done, done + args.trials):
                if trial > done:  # the first was checked above; the disk may have filled or the file changed since
                    logged = deploy_log.check_appendable(args.log, "--log")
                    if logged != trial:
                        raise deploy_log.DeployLogError(f"--log {args.log}: holds {logged} trials where {trial} "
                                                        "were expected (another deploy writing to it?)")
                obs = rig.reset(seed=seeds[trial])
                _wait_for_operator(rig, f"trial {trial}: robots at their start poses, set the scene", False)
                for _ in range(args.steps):
                    a = policy(obs)
                    rig.act({"r1": a[:2], "r2": a[2:]})
                    obs = rig.observe()
                    if rig.done:
                        break
                rig.stop()
                ok = rig.outcome()
                if ok is None:
                    ok = _ask_yes_no(f"trial {trial}: did the task succeed?")
                try:
                    deploy_log.append_trial(args.log, trial, ok)
                except (OSError, deploy_log.DeployLogError) as e:
                    # checked just before the trial, yet the write failed: the outcome goes to the screen instead
                    reason = (e.strerror or str(e)) if isinstance(e, OSError) else str(e)
                    raise deploy_log.DeployLogError(
                        f"--log {args.log}: the outcome of trial {trial} ({ok}) could not be appended ({reason}); "
                        f"add the row '{trial},{ok}' yourself once the log can take it") from None
                successes += ok
                bar.update(1)
    except KeyboardInterrupt:
        n = len(deploy_log.read_trials(args.log))
        print(f"interrupted: arms stopped; {n} trials in {args.log}", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f"{task} {args.method}: {successes}/{args.trials} successful; log {args.log} "
          f"({len(deploy_log.read_trials(args.log))} trials in all)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m lfdt.robot`` parser; add subcommands with an ``add_<name>_parser(subparsers)`` function."""
    parser = inputs.ArgumentParser(prog="python -m lfdt.robot",
                                     description="Talk to the myCobot 280 arms (README: Real robot).")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_check_parser(subparsers)
    add_move_parser(subparsers)
    add_calibrate_parser(subparsers)
    add_write_rig_config_parser(subparsers)
    add_record_random_parser(subparsers)
    add_record_demos_parser(subparsers)
    add_deploy_parser(subparsers)
    return parser


def _one_line(err: BaseException) -> str:
    """An error's message and its notes (what was kept, what to do) on one line."""
    text = " ".join(str(err).split("\n"))
    return "; ".join([text, *getattr(err, "__notes__", [])])


def main(argv: Sequence[str] | None = None) -> int:
    """Run one subcommand; returns the exit code (argparse exits 2 itself on bad arguments). Every ending but a bug
    is one line on stderr: ``refused: ...``, ``error: ...`` (exit 2) or ``interrupted`` (exit 130)."""
    try:
        from lfdt.rig.recording import RecordingMismatch
        from lfdt.robot.rig_config import RigConfigError  # light: pydantic and numpy; the heavy ones load per command

        args = build_parser().parse_args(argv)
        return args.func(args)
    except SafetyError as e:
        print(f"refused: {e}; that command was not sent", file=sys.stderr)
        return EXIT_FAILED
    except (ArmNotResponding, TrackingLost, RigConfigError, RecordingMismatch, StageError) as e:
        # StageError: a user-given file or folder that cannot be used (lfdt.inputs), a damaged model file
        print(f"error: {_one_line(e)}", file=sys.stderr)
        return EXIT_FAILED
    except EOFError:  # input() on a closed stdin: nobody to answer the operator's questions
        print("error: stdin closed while waiting for the operator (robots: run interactively, or --yes where "
              "offered)", file=sys.stderr)
        return EXIT_FAILED
    except OSError as e:  # a full disk, a folder where a file belongs, no permission: the OS names the path
        print(f"error: {inputs.os_error_message(e)}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
