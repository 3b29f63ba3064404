"""The real-robot guide (docs/real-robot.md), step by step, as a user without robots would dry-run it: a fake arm on a
pseudo-terminal, a video of a chessboard as the camera, the MuJoCo twin as the rig (``--sim``), then the DVC
commands of steps 5 and 6, ending with the real backend's twin report."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import smoke
import yaml
from test_tracker import K, _board_views, _chessboard_texture

from lfdt.robot import fake_mycobot as fm

GUIDE = smoke.ROOT / "docs" / "real-robot.md"


def _cli(project: Path, *args: str) -> str:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", "MUJOCO_GL": "egl"}
    proc = subprocess.run([sys.executable, "-m", "lfdt.robot", *args], cwd=project, env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, f"lfdt.robot {' '.join(args)}:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    return proc.stdout


def _digest(folder: Path) -> dict[str, str]:
    import hashlib

    return {f.name: hashlib.md5(f.read_bytes()).hexdigest() for f in sorted(folder.glob("*.pt"))}


def _guide() -> str:
    text = GUIDE.read_text()
    return text[text.index("# Real robot"):text.index("## The MuJoCo twin")]


def test_the_guide_step_by_step(tmp_path):
    guide = _guide()
    project = smoke.make_project(tmp_path / "project", commit=True)

    # 1. check each arm, move it (the fake arm speaks the arm's protocol on a pseudo-terminal)
    assert "python -m lfdt.robot check --port /dev/ttyUSB0" in guide
    with fm.FakeMyCobot("pty", angles=[1, 2, 3, 4, 5, 6]) as fake:
        assert _cli(project, "check", "--port", fake.device).startswith("angles: 1.00 2.00")
        _cli(project, "move", "--port", fake.device, "--angles", "0", "0", "0", "0", "0", "0", "--speed", "30")
        assert fake.angles == [0.0] * 6

    # 2. calibrate the camera from 25 views of a 9 x 6 chessboard (here a video, one view per 0.5 s)
    assert "calibrate --camera 4 --pattern 9 6 --square 0.025 --frames 25 --out calib.json" in guide
    squares, px, margin, sq = (10, 7), 60, 60, 0.025
    m = sq * margin / px
    views = _board_views(_chessboard_texture(squares, px, margin), squares[0] * sq + 2 * m,
                         squares[1] * sq + 2 * m, K, n=25, seed=2)
    video = tmp_path / "camera.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 2.0, views[0].shape[::-1])
    for v in views:
        writer.write(cv2.cvtColor(v, cv2.COLOR_GRAY2BGR))
    writer.release()
    _cli(project, "calibrate", "--camera", str(video), "--pattern", "9", "6", "--square", "0.025", "--frames", "25",
         "--out", "calib.json")
    calib = json.loads((project / "calib.json").read_text())
    assert abs(np.asarray(calib["camera_matrix"])[0][0] - K[0, 0]) < 0.05 * K[0, 0]

    # 3. describe the rig
    assert "write-rig-config --out rig.json --task block_push" in guide
    _cli(project, "write-rig-config", "--out", "rig.json", "--task", "block_push")
    assert json.loads((project / "rig.json").read_text())

    # 4. record random motion in all three domains and demonstrations in both pairings (the twin as the rig)
    assert re.search(r"for d in Y R1H HR2; do python -m lfdt.robot record-random --rig rig.json --domain \$d", guide)
    real = project / "data/real/block_push"
    for d in ("Y", "R1H", "HR2"):
        _cli(project, "record-random", "--sim", "--rig", "rig.json", "--domain", d, "--episodes", "6", "--steps",
             "20", "--out", str(real / f"random_{d}"))
    for pairing in ("R1H", "HR2"):
        assert f"record-demos --rig rig.json --pairing {pairing} --episodes 10" in guide
        _cli(project, "record-demos", "--sim", "--rig", "rig.json", "--pairing", pairing, "--episodes", "2",
             "--out", str(real / f"demos_{pairing}"))

    # 5. train on the recordings (the deploy logs do not exist yet)
    step5 = "dvc exp run -S twin.backend=real -S 'twin.tasks=[block_push]' twin_train"
    assert step5 in guide
    out = smoke.dvc(["exp", "run", "-S", "twin.backend=real", "-S", "twin.tasks=[block_push]", "twin_train"], project)
    assert "'twin_train@block_push'" in out and "'twin_train@peg_insertion'" not in out
    first = yaml.safe_load((project / "params.yaml").read_text())["twin"]["seeds"][0]
    models = project / f"models/twin/block_push/s{first}"
    assert (models / "dynamics.pt").exists()

    # 6. deploy both methods (on the twin), then the report from the deploy logs
    deployed = _digest(models)
    assert "python -m lfdt.robot deploy --rig rig.json --task block_push --method $m" in guide
    for method in ("lfdt", "bc_no_translation"):
        _cli(project, "deploy", "--sim", "--rig", "rig.json", "--task", "block_push", "--method", method,
             "--models", str(models), "--trials", "3", "--log", str(real / f"deploy_{method}.csv"))
    step6 = "dvc exp run -S twin.backend=real -S 'twin.tasks=[block_push]' twin_report"
    assert step6 in guide
    out = smoke.dvc(["exp", "run", "-S", "twin.backend=real", "-S", "twin.tasks=[block_push]", "twin_report"],
                    project)
    # the deploy logs lie in data/real/ beside the recordings, so the recordings are imported and trained on again:
    # the same models as those that were deployed
    assert "'twin_evaluate@block_push'" in out
    assert _digest(models) == deployed, "retraining on the same recordings gave other models than those deployed"
    report = (project / "reports/twin.md").read_text()
    assert "(the robots)" in report and "block_push" in report and "peg_insertion" not in report
    rows = (project / "reports/twin_runs.csv").read_text().splitlines()
    assert len(rows) == 1 + 2 * 3  # both methods, three logged trials each

    # new recordings rerun the twin stages: data/real is a dependency
    _cli(project, "record-demos", "--sim", "--rig", "rig.json", "--pairing", "R1H", "--episodes", "1", "--seed",
         "1", "--out", str(real / "demos_R1H_more"))
    status = smoke.dvc(["status", "twin_collect@block_push"], project)
    assert "data/real" in status and "modified" in status
