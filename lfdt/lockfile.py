"""dvc.lock hygiene: drop the entries of stages that dvc.yaml no longer defines.

DVC keeps a stage's lock entry after the stage leaves dvc.yaml (treeverse/dvc#5293), for example when a
matrix is reshaped. Nothing reads those entries, but every `dvc status` and `dvc repro` parses them twice:
110 stale entries made up 55 % of our dvc.lock and about half of a no-op `dvc repro`'s time.

    python -m lfdt.lockfile          # list stale entries, exit 1 if there are any
    python -m lfdt.lockfile --prune  # remove them (the other entries are written back byte for byte)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def defined_stages(root: str | Path = ".") -> set[str]:
    """Names of every stage dvc.yaml defines, matrix entries expanded (``bc_evaluate@lfdt-100``)."""
    from dvc.repo import Repo

    with Repo(str(root)) as repo:
        return {stage.addressing for stage in repo.index.stages}


def stale_stages(lock: dict, defined: set[str]) -> list[str]:
    """Lock entries (in file order) whose stage is not in ``defined``."""
    if not isinstance(lock.get("stages"), dict):
        raise ValueError("dvc.lock has no 'stages' mapping")
    return [name for name in lock["stages"] if name not in defined]


def prune(lock_path: str | Path, defined: set[str]) -> list[str]:
    """Remove stale entries from a lock file with DVC's own writer; returns the removed names."""
    from dvc.utils.serialize import dump_yaml, load_yaml

    lock = load_yaml(str(lock_path))
    stale = stale_stages(lock, defined)
    if stale:
        lock["stages"] = {k: v for k, v in lock["stages"].items() if k not in set(stale)}
        dump_yaml(str(lock_path), lock)
    return stale


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--prune", action="store_true", help="remove the stale entries (default: only list them)")
    ap.add_argument("--root", default=".", help="repository root (default: the current directory)")
    args = ap.parse_args(argv)
    root = Path(args.root)
    lock_path = root / "dvc.lock"
    if not lock_path.exists():
        print(f"error: {lock_path} does not exist", file=sys.stderr)
        return 2
    defined = defined_stages(root)
    if args.prune:
        removed = prune(lock_path, defined)
        print(f"removed {len(removed)} stale entries from {lock_path}" + (f": {', '.join(removed)}" if removed else ""))
        return 0
    from dvc.utils.serialize import load_yaml

    stale = stale_stages(load_yaml(str(lock_path)), defined)
    for name in stale:
        print(name)
    print(f"{len(stale)} stale entries in {lock_path}" + (" (remove them with --prune)" if stale else ""),
          file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
