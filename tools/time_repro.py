"""Time a full ``dvc repro`` and write reports/run_time.json (CPU model, cores, date, commit, minutes).

    python tools/time_repro.py --clone        # in a fresh clone of HEAD (the issue's measure), with make setup
    python tools/time_repro.py                # here, every stage forced (dvc repro --force)

With ``--clone`` the clone's reports/ (every report of the run) are copied back here afterwards, so the workspace
holds what the timed run computed; without it the workspace's run is the timed one. The log of the run goes to
``--log``.
"""

import lfdt.numerics  # noqa: F401

import argparse
import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from lfdt import numerics

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clone", action="store_true", help="run in a fresh clone of HEAD (make setup, then dvc repro)")
    ap.add_argument("--log", type=Path, default=Path("/tmp/time_repro.log"))
    args = ap.parse_args()
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                            check=True).stdout.strip()
    env = {k: v for k, v in os.environ.items() if k not in numerics.PINNED_ENV}
    env["MUJOCO_GL"] = "egl"
    with args.log.open("w") as log:
        if args.clone:
            work = Path(tempfile.mkdtemp(prefix="lfdt-clone-")) / "lfdt"
            subprocess.run(["git", "clone", "-q", "--", str(ROOT), str(work)], check=True)
            t0 = time.perf_counter()
            subprocess.run(["make", "setup"], cwd=work, stdout=log, stderr=subprocess.STDOUT, check=True, env=env)
            setup_s = time.perf_counter() - t0
            env["PATH"] = f"{work / '.venv/bin'}:{env['PATH']}"
            cmd = ["dvc", "repro"]
        else:
            work, setup_s = ROOT, None
            env["PATH"] = f"{ROOT / '.venv/bin'}:{env['PATH']}"
            cmd = ["dvc", "repro", "--force"]
        t0 = time.perf_counter()
        r = subprocess.run(cmd, cwd=work, stdout=log, stderr=subprocess.STDOUT, env=env)
        wall = time.perf_counter() - t0
    if r.returncode != 0:
        sys.exit(f"tools/time_repro.py: `{' '.join(cmd)}` failed with exit code {r.returncode}; see {args.log}")
    if args.clone:
        # the run's results into this workspace: its reports and lock, its cache (so `dvc checkout` restores every
        # output), and its MLflow store beside ours
        shutil.copytree(work / "reports", ROOT / "reports", dirs_exist_ok=True)
        shutil.copy2(work / "dvc.lock", ROOT / "dvc.lock")
        shutil.copytree(work / ".dvc" / "cache", ROOT / ".dvc" / "cache", dirs_exist_ok=True)
        if (work / "mlflow.db").exists():
            shutil.copy2(work / "mlflow.db", ROOT / "mlflow-clone-run.db")
    doc = {"minutes": wall / 60, "setup_minutes": None if setup_s is None else setup_s / 60,
           "how": "fresh clone: make setup, then dvc repro" if args.clone else "workspace: dvc repro --force",
           "cpu_model": numerics.cpu_model(), "cpu_isa": numerics.isa(), "cores": os.cpu_count(),
           "numerics": numerics.mode(), "date": datetime.date.today().isoformat(), "commit": commit}
    (ROOT / "reports" / "run_time.json").write_text(json.dumps(doc, indent=2) + "\n")
    print(json.dumps(doc, indent=2))


if __name__ == "__main__":
    main()
