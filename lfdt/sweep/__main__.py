"""``python -m lfdt.sweep``: run the pipeline of this workspace's params through a Ray cluster.

Examples::

    python -m lfdt.sweep --list
    MLFLOW_TRACKING_URI=http://head:5000 python -m lfdt.sweep --address head:6379 --remote-url s3://bucket/lfdt
    # six seeds and two weights of L_dyn: four points, each recorded as a DVC experiment (dvc exp show)
    python -m lfdt.sweep --address head:6379 --remote-url s3://bucket/lfdt \
        --set grid.seeds=[3,4,5],[3,4,5,6,7,8] --set translator.lambda_dyn=10,1
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from lfdt.config import ParamsError
from lfdt.errors import StageError
from lfdt.inputs import ArgumentParser, one_line_errors, positive_float
from lfdt.sweep.chain import Remote
from lfdt.sweep.coordinator import check_project, describe, run_points, run_sweep
from lfdt.sweep.plan import make_plan
from lfdt.sweep.points import expand


def parser() -> argparse.ArgumentParser:
    """The command line."""
    p = ArgumentParser(prog="python -m lfdt.sweep", description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--list", action="store_true", help="print the plan (shared stages, chains, final stages), run "
                                                       "nothing")
    p.add_argument("--address", default=os.environ.get("RAY_ADDRESS"),
                   help="the Ray cluster (host:port of its head; default $RAY_ADDRESS, else a Ray instance on this "
                        "machine)")
    p.add_argument("--remote", default="sweep", help="name of the DVC remote every node uses (default 'sweep')")
    p.add_argument("--remote-url", help="URL of that remote (e.g. s3://bucket/lfdt); without it --remote must be a "
                                        "remote of the committed .dvc/config")
    p.add_argument("--endpoint-url", help="S3-compatible endpoint of the remote (MinIO, Ceph, a local test server)")
    p.add_argument("--cpus-per-chain", type=positive_float, default=1.0, help="Ray CPUs one chain takes (default 1)")
    p.add_argument("--repo-url", help="where workers clone the project from (default this workspace's path: right "
                                      "when every node sees it, e.g. one machine or a shared file system)")
    p.add_argument("--workdir", help="directory for the clones on each worker (default its temporary directory)")
    p.add_argument("--forward-env", action="append", default=[], metavar="VAR",
                   help="also set VAR, as it is here, for every chain's stages (repeatable)")
    p.add_argument("-S", "--set", action="append", default=[], metavar="KEY=V1[,V2...]", dest="sets",
                   help="sweep these values of a params.yaml key (repeatable; every combination is a point, "
                        "recorded as a DVC experiment; lists in brackets: grid.seeds=[3,4,5],[3,4,5,6,7,8])")
    p.add_argument("--chains", nargs="+", metavar="CHAIN", help="run only these chains (names as --list prints "
                                                                "them), not the final stages")
    return p


def main(argv: list[str] | None = None) -> int:
    """Parse, run, print a summary; errors that say all a user needs exit 2 with one line, Ctrl-C one line."""
    args = parser().parse_args(argv)
    return one_line_errors(lambda: _run(args, Path.cwd()), "chains that finished are kept in the run cache; the "
                           "same command goes on from them", refused=(ParamsError,))


def _run(args: argparse.Namespace, root: Path) -> int:
    if args.list:
        check_project(root)
        points = expand((root / "params.yaml").read_text(), args.sets) if args.sets else []
        print(describe(make_plan(root)))  # of the workspace's params: a point's grid may add chains
        for i, point in enumerate(points, 1):
            print(f"point {i} ({point.name}): {point.describe()}")
        return 0
    if args.endpoint_url and not args.remote_url:
        raise StageError("--endpoint-url needs --remote-url")
    if args.sets and args.chains:
        raise StageError("--chains runs part of one point's sweep: it cannot be combined with --set")
    remote = Remote(args.remote, args.remote_url, args.endpoint_url)
    options = dict(address=args.address, cpus_per_chain=args.cpus_per_chain, repo_url=args.repo_url,
                   forward_env=args.forward_env, workdir=args.workdir)
    if args.sets:
        summary = run_points(root, args.sets, remote, **options)
        print(f"sweep done in {summary['wall_s']:.0f} s: {len(summary['points_run'])} points recorded as "
              f"experiments ({', '.join(summary['points_run']) or 'none new'}); `dvc exp apply <name>` brings "
              f"one into the workspace")
        return 0
    summary = run_sweep(root, remote, only=args.chains, **options)
    print(f"sweep done in {summary['wall_s']:.0f} s: {len(summary['chains_run'])} chains run, "
          f"{len(summary['chains_skipped'])} finished earlier; the final `dvc repro` ran "
          f"{', '.join(summary['final_ran']) or 'nothing'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
