"""Wall time of a sweep through a local Ray cluster (head + worker nodes, one CPU each) against a plain `dvc repro` of
the same params, both in one run on this machine, and whether they give the same tables.

The params are the smoke params (tests/smoke_params.yaml) unless ``--params`` names another params.yaml. The
servers are those of the tests (tests/services.py: PostgreSQL, an S3 server, MLflow on both, Ray), started here
and stopped by process id. The sweep's time includes building the shared stages and publishing them; starting
the servers is not counted. Writes benchmarks/results/sweep_vs_repro.json.
"""

from __future__ import annotations

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import services  # noqa: E402
import smoke  # noqa: E402

BUCKET = "lfdt-bench"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--params", type=Path, help="a params.yaml to use instead of the smoke params")
    ap.add_argument("--workers", type=int, default=1, help="Ray worker nodes beside the head (one CPU each)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/sweep_vs_repro.json")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="lfdt-bench-sweep-"))
    plain, coord = (smoke.make_project(work / name, commit=True) for name in ("plain", "coordinator"))
    if args.params:
        for d in (plain, coord):
            (d / "params.yaml").write_text(args.params.read_text())

    t = time.monotonic()
    smoke.dvc(["repro"], plain, timeout=24 * 3600)
    plain_s = time.monotonic() - t

    logs = work / "logs"
    logs.mkdir()
    with services.postgres(logs) as pg, services.s3_server(logs, BUCKET) as s3, \
            services.mlflow_server(logs, pg, f"s3://{BUCKET}/mlartifacts", s3) as ml, \
            services.ray_cluster(logs, workers=args.workers, env=services.S3_ENV) as address:
        env = {**os.environ, **services.S3_ENV, "MLFLOW_TRACKING_URI": ml, "DVC_NO_ANALYTICS": "1",
               "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
        t = time.monotonic()
        proc = subprocess.run([sys.executable, "-m", "lfdt.sweep", "--address", address, "--remote-url",
                               f"s3://{BUCKET}/dvc", "--endpoint-url", s3], cwd=coord, env=env,
                              capture_output=True, text=True)
        sweep_s = time.monotonic() - t
    if proc.returncode != 0:
        raise SystemExit(f"the sweep failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    same = {table: (plain / table).read_bytes() == (coord / table).read_bytes() for table in smoke.TABLES}
    result = {"plain_repro_s": round(plain_s, 1), "sweep_s": round(sweep_s, 1),
              "ratio_sweep_over_plain": round(sweep_s / plain_s, 3), "same_tables": same,
              "ray_nodes": 1 + args.workers, "params": str(args.params or "tests/smoke_params.yaml"),
              "cpus": os.cpu_count(), "machine": platform.platform()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
