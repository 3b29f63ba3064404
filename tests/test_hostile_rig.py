"""Hostile input for the real-robot commands (``python -m lfdt.robot``) and the stage that reads their logs: a rig
config whose camera files are missing or not what they should be, a deploy log that cannot take the next outcome,
a policy without its sidecar, an output that is a file where a folder belongs, a full disk, Ctrl-C. Each ends with
one line on stderr naming the file or argument and what was expected, exit 2 (130 for Ctrl-C), within 10 s, before
anything ran: no trial of a policy whose outcome could not be kept, and no file changed. A new case is one row of
:data:`CASES`.

The commands run in-process on the twin (``--sim``) with tiny untrained policies; the real rig is never built here
(building it would mean the camera and calibration passed their checks).
"""

from __future__ import annotations

import errno
import importlib.util
import io
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from tqdm import tqdm

from lfdt import bc, stage, twin
from lfdt.rig.sim import SimRig
from lfdt.robot import cli
from lfdt.robot.real_rig import RealRig
from lfdt.robot.rig_config import example_rig_config
from lfdt.tasks import registry

ROOT = Path(__file__).resolve().parents[1]
GOOD_CALIBRATION = {"format_version": 1, "camera_matrix": [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0, 0, 1]],
                    "dist_coeffs": [0, 0, 0, 0, 0], "image_size": [640, 480], "rms_px": None, "n_views": 0,
                    "method": "manual"}
LOG = "trial,success\r\n0,True\r\n"
"""A good deploy log of one trial."""


# ------------------------------------------------------------------------------------------- building the inputs


def tiny_policies(models: Path) -> Path:
    """Untrained policies of both methods for block_push (the deploy command only needs them to act)."""
    tl = registry.get("block_push").layout
    for method in twin.TWIN_METHODS:
        member = bc.BCMember(tl.state_columns("Y"), tl.action_columns("Y"), [4])
        bc.BCPolicy([member], tl, action_bounds=None).save(models / method, {"bc": {"hidden": [4]},
                                                                             "members": ["all"]})
    return models


def rig(tmp: Path, calibration: bytes | None = None, source: int | str = "video.avi") -> Path:
    """A rig config with its camera files in ``tmp``: the calibration's bytes (None: no file), the camera."""
    cfg = example_rig_config("block_push")
    cfg["camera"].update({"calibration": "calib.json", "source": source})
    (tmp / "video.avi").write_bytes(b"not looked at before the arms connect")
    if calibration is not None:
        (tmp / "calib.json").write_bytes(calibration)
    path = tmp / "rig.json"
    path.write_text(json.dumps(cfg))
    return path


def record(tmp: Path, *rig_args: str, out: str = "rec", command: str = "record-random") -> list[str]:
    what = ["--domain", "Y", "--steps", "2"] if command == "record-random" else ["--pairing", "R1H"]
    return [command, *rig_args, *what, "--episodes", "1", "--out", str(tmp / out)]


def with_rig(calibration: bytes | None, source: int | str = "video.avi",
             command: str = "record-random") -> Callable[[Path], list[str]]:
    def build(tmp: Path) -> list[str]:
        path = rig(tmp, calibration, source)
        if command == "deploy":
            argv = deploy(log=LOG.encode())(tmp)
            argv[argv.index("--sim")] = f"--rig={path}"
            return argv
        return record(tmp, "--rig", str(path), command=command)
    return build


def with_rig_text(old: str, new: str) -> Callable[[Path], list[str]]:
    """record-random with a rig config (good camera files) whose JSON text has its first ``old`` replaced by ``new``."""
    def build(tmp: Path) -> list[str]:
        path = rig(tmp, json.dumps(GOOD_CALIBRATION).encode())
        text = path.read_text()
        assert old in text, old
        path.write_text(text.replace(old, new, 1))
        return record(tmp, "--rig", str(path))
    return build


def deploy(log: bytes | None = None, log_path: str = "deploy_lfdt.csv", sidecar: bool = True,
           trials: int = 1) -> Callable[[Path], list[str]]:
    """``deploy --sim`` of tiny policies, appending to ``log_path`` (under tmp unless absolute) holding ``log``."""
    def build(tmp: Path) -> list[str]:
        models = tiny_policies(tmp / "models")
        if not sidecar:
            (models / "lfdt" / "all.json").unlink()
        path = tmp / log_path
        if log is not None:
            path.write_bytes(log)
        return ["deploy", "--sim", "--task", "block_push", "--method", "lfdt", "--models", str(models),
                "--trials", str(trials), "--log", str(path)]
    return build


def stage_log(log: bytes | None, folder: bool = False, missing: bool = False) -> Callable[[Path], list[str]]:
    """The twin_evaluate stage (backend 'real') reading the deploy logs: lfdt's holds ``log`` (or is a folder, or is
    missing), the other method's is a good one."""
    def build(tmp: Path) -> list[str]:
        task = tmp / "real" / "block_push"
        task.mkdir(parents=True)
        for method in twin.TWIN_METHODS:
            (task / f"deploy_{method}.csv").write_text(LOG)
        path = task / "deploy_lfdt.csv"
        if folder or missing:
            path.unlink()
        if folder:
            path.mkdir()
        elif log is not None:
            path.write_bytes(log)
        return ["stage:twin_evaluate", str(tmp / "real")]
    return build


def disk_full(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every file system reports no free block (as a full one does to an ordinary user)."""
    real = os.statvfs

    def full(path):
        st = real(path)
        return os.statvfs_result((st.f_bsize, st.f_frsize, st.f_blocks, 0, 0, *tuple(st)[5:]))

    monkeypatch.setattr(os, "statvfs", full)


def fail_writes(monkeypatch: pytest.MonkeyPatch) -> None:
    """The disk fills while the trial runs: the log's append fails with ENOSPC."""
    from lfdt import csvlog

    def write(fd, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(csvlog.os, "write", write)


def interrupt_at(target: str) -> Callable[[pytest.MonkeyPatch], None]:
    """Ctrl-C when ``target`` (a dotted name) is called."""
    def patch(monkeypatch: pytest.MonkeyPatch) -> None:
        def ctrl_c(*args, **kwargs):
            raise KeyboardInterrupt

        monkeypatch.setattr(target, ctrl_c)
    return patch


# ------------------------------------------------------------------------------------------------------ the table


@dataclass(frozen=True)
class Case:
    id: str
    argv: Callable[[Path], list[str]]
    """Builds the hostile input under tmp and returns the command line."""
    names: tuple[str, ...]
    """What the one line on stderr must say; ``{tmp}`` is the test's folder."""
    code: int = 2
    ran: int = 0
    """Trials or episodes started (the twin's resets)."""
    patch: Callable[[pytest.MonkeyPatch], None] | None = None
    unchanged: bool = True
    """No file under tmp changed (a deploy log byte for byte)."""


NOT_UTF8 = b"trial,success\r\n0,Tr\xffue\r\n"
CALIBRATION = "camera.calibration {tmp}/calib.json"
CASES = [
    # rig JSON: the camera's calibration file and the camera itself, checked before any arm is connected
    Case("calibration-missing", with_rig(None), (CALIBRATION, "no such file", "--rig")),
    Case("calibration-garbage", with_rig(bytes(range(256))), (CALIBRATION, "not UTF-8")),
    Case("calibration-empty", with_rig(b""), (CALIBRATION, "is empty")),
    Case("calibration-not-json", with_rig(b"{camera_matrix: 1"), (CALIBRATION, "is not JSON (line 1 column 2")),
    Case("calibration-a-list", with_rig(b"[1, 2, 3]"), (CALIBRATION, "holds a JSON list, not an object")),
    Case("calibration-key-missing", with_rig(json.dumps({"image_size": [640, 480]}).encode()),
         (CALIBRATION, "has no key 'camera_matrix'")),
    Case("calibration-field-a-string", with_rig(json.dumps({**GOOD_CALIBRATION, "camera_matrix": "K"}).encode()),
         (CALIBRATION, "camera_matrix: 'K' is not a list of numbers")),
    Case("calibration-quoted-numbers",
         with_rig(json.dumps({**GOOD_CALIBRATION, "image_size": ["640", "480"]}).encode()),
         (CALIBRATION, "image_size: ['640', '480'] is not [width, height]")),
    Case("calibration-matrix-2x2",
         with_rig(json.dumps({**GOOD_CALIBRATION, "camera_matrix": [[1, 0], [0, 1]]}).encode()),
         (CALIBRATION, "camera_matrix: 4 numbers, not 3x3")),
    Case("calibration-a-folder", lambda tmp: (tmp / "calib.json").mkdir() or with_rig(None)(tmp),
         (CALIBRATION, "is a folder, not a file")),
    # rig JSON: what JSON parsers and a loose schema let through
    Case("rig-infinite-step", with_rig_text('"max_step_deg": 15.0', '"max_step_deg": Infinity'),
         ("{tmp}/rig.json: arms.r1.max_step_deg: Input should be a finite number",)),
    Case("rig-key-twice", with_rig_text('"control_period_s": 0.1', '"control_period_s": 0.1, "control_period_s": 5'),
         ("{tmp}/rig.json: has the key 'control_period_s' twice",)),
    Case("calibration-key-twice", with_rig(json.dumps(GOOD_CALIBRATION).replace(
        '"image_size"', '"image_size": [1, 1], "image_size"').encode()),
         (CALIBRATION, "has the key 'image_size' twice")),
    Case("rig-empty-port", with_rig_text('"port": "/dev/ttyUSB0"', '"port": ""'),
         ("{tmp}/rig.json: arms.r1.port: String should have at least 1 character",)),
    Case("rig-one-port-two-arms", with_rig_text('"/dev/ttyUSB1"', '"/dev/ttyUSB0"'),
         ("{tmp}/rig.json: arms.r1 and arms.r2 are both connected at '/dev/ttyUSB0'",)),
    Case("camera-index-absent", with_rig(json.dumps(GOOD_CALIBRATION).encode(), source=97),
         ("camera.source 97: no camera /dev/video97",)),
    Case("camera-video-missing", with_rig(json.dumps(GOOD_CALIBRATION).encode(), source="gone.avi"),
         ("camera.source {tmp}/gone.avi: no such file",)),
    Case("record-demos-calibration-empty", with_rig(b"", command="record-demos"), (CALIBRATION, "is empty")),
    Case("deploy-calibration-a-list", with_rig(b"[]", command="deploy"), (CALIBRATION, "JSON list")),
    # deploy: the log must take the outcome before the trial runs
    Case("log-a-folder", lambda tmp: (tmp / "logs").mkdir() or deploy(log_path="logs")(tmp),
         ("--log {tmp}/logs: is a folder, not a file",)),
    Case("log-dev-full", deploy(log_path="/dev/full"), ("--log /dev/full: is a character device",)),
    # /proc/self/comm: a regular file its process may write, as root or not (it is the process's name)
    Case("log-in-proc", deploy(log_path="/proc/self/comm"), ("--log /proc/self/comm: is on a virtual file system",)),
    Case("log-under-a-file", lambda tmp: (tmp / "f").write_text("x") and deploy(log_path="f/deploy.csv")(tmp),
         ("--log {tmp}/f/deploy.csv: a folder on its path is a file",)),
    Case("log-disk-full", deploy(log=LOG.encode()), ("--log {tmp}/deploy_lfdt.csv: the disk holding it is full",),
         patch=disk_full),
    Case("log-not-utf8", deploy(log=NOT_UTF8), ("--log {tmp}/deploy_lfdt.csv: line 2: byte 0xff",)),
    Case("log-header-not-utf8", deploy(log=b"tri\xe9l,success\r\n"), ("{tmp}/deploy_lfdt.csv, line 1",)),
    Case("log-other-header", deploy(log=b"trial;success\n0;True\n"), ("{tmp}/deploy_lfdt.csv: header",)),
    Case("log-cr-only-is-appended", deploy(log=b"trial,success\r0,True\r"), (), code=0, ran=1, unchanged=False),
    Case("log-write-fails-mid-run", deploy(log=LOG.encode()),
         ("--log {tmp}/deploy_lfdt.csv: the outcome of trial 1", "No space left on device", "add the row '1,"),
         ran=1, patch=fail_writes),
    Case("log-full-of-trials", deploy(log=("trial,success\r\n" + "".join(f"{i},True\r\n" for i in range(99_999))
                                           ).encode(), trials=5),
         ("--trials 5: --log {tmp}/deploy_lfdt.csv holds 99999 already", "at most 1 more")),
    # deploy: the policy's files
    Case("policy-of-another-task", lambda tmp: [a if a != "block_push" else "peg_insertion"
                                                for a in deploy(log=LOG.encode())(tmp)],
         ("--models {tmp}/models: {tmp}/models/lfdt: the policy reads or writes columns that domain Y of this task "
          "does not have",)),
    Case("policy-sidecar-missing", deploy(log=LOG.encode(), sidecar=False),
         ("--models {tmp}/models: {tmp}/models/lfdt/all.json is missing",)),
    # a folder expected, a file given
    Case("record-random-out-a-file", lambda tmp: (tmp / "rec").write_text("x") and record(tmp, "--sim", "--task",
         "block_push"), ("--out {tmp}/rec: is a file, not a folder",)),
    Case("record-demos-out-a-file", lambda tmp: (tmp / "rec").write_text("x") and record(
        tmp, "--sim", "--task", "block_push", command="record-demos"), ("--out {tmp}/rec: is a file, not a folder",)),
    Case("record-out-meta-garbage", lambda tmp: (tmp / "rec").mkdir() or (tmp / "rec" / "_meta.json").write_bytes(
        b"\x00\xff") and record(tmp, "--sim", "--task", "block_push"), ("{tmp}/rec/_meta.json: line 1",)),
    Case("record-out-disk-full", lambda tmp: record(tmp, "--sim", "--task", "block_push"),
         ("--out {tmp}/rec: the disk holding it is full",), patch=disk_full),
    Case("calibrate-out-a-folder", lambda tmp: (tmp / "v.avi").write_text("") or (tmp / "out").mkdir() or [
        "calibrate", "--camera", str(tmp / "v.avi"), "--pattern", "9", "6", "--square", "0.02", "--out",
        str(tmp / "out")], ("--out {tmp}/out: is a folder, not a file",)),
    Case("calibrate-charuco-marker-too-big", lambda tmp: ["calibrate", "--camera", str(tmp / "none.avi"), "--pattern",
         "5", "4", "--square", "0.02", "--charuco", "--marker", "0.05", "--out", str(tmp / "c.json")],
         ("--marker 0.05: the marker must be smaller than its square",)),
    Case("calibrate-board-too-small", lambda tmp: ["calibrate", "--camera", str(tmp / "none.avi"), "--pattern", "-3",
         "5", "--square", "0.02", "--out", str(tmp / "c.json")],
         ("--pattern -3 5: a chessboard needs at least 3 inner corners",)),
    Case("calibrate-more-views-than-frames", lambda tmp: ["calibrate", "--camera", str(tmp / "none.avi"), "--pattern",
         "9", "6", "--square", "0.02", "--frames", "5", "--min-views", "6", "--out", str(tmp / "c.json")],
         ("--min-views 6: more views than --frames 5 grabs",)),
    Case("calibrate-camera-missing", lambda tmp: ["calibrate", "--camera", str(tmp / "none.avi"), "--pattern", "9",
         "6", "--square", "0.02", "--out", str(tmp / "c.json")], ("--camera {tmp}/none.avi: no such file",)),
    # a pipe, not /dev/full: a write that goes wrong replaces the target, and as root that would be the device
    Case("write-rig-config-a-pipe", lambda tmp: os.mkfifo(tmp / "p") or ["write-rig-config", "--out", str(tmp / "p"),
         "--force"], ("--out {tmp}/p: is a pipe, not a file",)),
    # the stage that reads the deploy logs
    Case("stage-log-not-utf8", stage_log(NOT_UTF8), ("{tmp}/real/block_push/deploy_lfdt.csv: line 2: byte 0xff",)),
    Case("stage-log-a-folder", stage_log(None, folder=True),
         ("{tmp}/real/block_push/deploy_lfdt.csv: is a folder, not a file",)),
    Case("stage-log-bad-row", stage_log(b"trial,success\n0,yes\n"), ("{tmp}/real/block_push/deploy_lfdt.csv, line 2",)),
    Case("stage-log-missing", stage_log(None, missing=True),
         ("no deployment log {tmp}/real/block_push/deploy_lfdt.csv",)),
    # Ctrl-C: one line, exit 130, wherever it lands
    Case("ctrl-c-while-loading", deploy(log=LOG.encode()), ("interrupted",), code=130,
         patch=interrupt_at("lfdt.robot.cli.build_parser")),
    Case("ctrl-c-during-a-trial", deploy(log=LOG.encode()), ("interrupted: arms stopped; 1 trials in",), code=130,
         ran=1, patch=interrupt_at("lfdt.rig.sim.SimRig.act")),
]


def _run_stage(real_dir: str) -> int:
    """The twin_evaluate stage's reading of the logs, in the frame every stage's errors go through."""
    spec = importlib.util.spec_from_file_location("twin_evaluate_stage", ROOT / "stages" / "twin_evaluate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    try:
        stage.main(lambda: module.real_trials("block_push", real_dir))
    except SystemExit as e:
        return int(e.code)
    return 0


def _files(tmp: Path) -> dict[str, bytes]:
    return {str(p): p.read_bytes() for p in sorted(tmp.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_hostile_rig_input_ends_in_one_line(case: Case, tmp_path: Path, monkeypatch, capsys) -> None:
    tmp = tmp_path
    argv = case.argv(tmp)
    before = _files(tmp)
    resets = []
    real_reset = SimRig.reset
    monkeypatch.setattr(SimRig, "reset", lambda self, seed=None: resets.append(seed) or real_reset(self, seed))

    def no_real_rig(*args, **kwargs):
        raise AssertionError("the real rig was built: its camera files passed their checks")

    monkeypatch.setattr(RealRig, "__init__", no_real_rig)
    # a progress bar would add lines to stderr; this one counts (the recording loop reads its count) out of sight
    monkeypatch.setattr(cli, "_progress", lambda total, unit, desc: tqdm(total=total, file=io.StringIO()))
    monkeypatch.delenv("DVC_STAGE", raising=False)
    monkeypatch.setattr("sys.argv", ["twin_evaluate", str(tmp)])  # the stage's lock is named after its command line
    if case.patch is not None:
        case.patch(monkeypatch)
    capsys.readouterr()
    start = time.monotonic()
    code = _run_stage(argv[1]) if argv[0] == "stage:twin_evaluate" else cli.main(argv)
    elapsed = time.monotonic() - start
    err = capsys.readouterr().err
    assert code == case.code, err
    assert "Traceback" not in err
    lines = err.splitlines()
    if case.code:
        assert len(lines) == 1, err
        assert lines[0].startswith("interrupted" if case.code == 130 else "error: "), err
        for text in case.names:
            assert text.format(tmp=tmp) in lines[0]
    assert len(resets) == case.ran, "a trial or an episode ran"
    assert elapsed < 10
    if case.unchanged:
        assert _files(tmp) == before, "a file changed"
    if case.id == "log-cr-only-is-appended":  # the outcome is kept, in the file's own line ending
        log = tmp / "deploy_lfdt.csv"
        assert log.read_bytes().startswith(b"trial,success\r0,True\r1,")
        assert log.read_bytes().endswith(b"\r") and not log.read_bytes().endswith(b"\n")
