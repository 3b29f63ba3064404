"""``python -m lfdt.restore [STAGE ...]``: bring back the outputs that DVC removed, as ``dvc.lock`` names them.

DVC removes a stage's outputs before it runs the stage; when the stage then fails, ``dvc checkout`` brings back the
cached ones but skips those ``dvc.yaml`` marks ``cache: false``. Of a stage whose ``cache: false`` outputs are all
metrics or plots (the experts' curves and ``reports/experts.json``, the dynamics curve), DVC's run cache keeps a copy
in the same local cache whenever the stage succeeded: this command checks out the cached outputs and copies those
back from that copy, by the hashes ``dvc.lock`` names, so results never committed to git come back as well. DVC keeps
no copy of the ``cache: false`` outputs of the four stages that also have plain ones (``fingerprint``, ``report``,
``register_policies``, ``twin_report``: DVC does not run-cache them), nor of any in a fresh clone: such an output
comes back from the last commit when the version there is the one ``dvc.lock`` names (git's index untouched);
otherwise it is named, with the commands that bring back its last committed version or make it again.
A ``cache: false`` output that is in the workspace is left as it is (it may be newer than ``dvc.lock``); a cached one
is checked out as ``dvc checkout`` does (files a failing stage half-wrote into it are refused by name, and replaced
with ``--force``).

Examples::

    python -m lfdt.restore                       # every stage of dvc.lock
    python -m lfdt.restore collect_demos report
    python -m lfdt.restore --force fit_dynamics  # also replace what the failing stage half-wrote into models/
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path

from lfdt.errors import InputError, StageError, first_line
from lfdt.inputs import ArgumentParser, one_line_errors


class NotRestorable(StageError):
    """Outputs that ``dvc.lock`` names but neither the cache nor the run cache holds."""


@dataclass
class Restored:
    """What :func:`restore` did, by output path (relative to the project)."""

    checked_out: list[str] = field(default_factory=list)
    """Cached outputs that ``dvc checkout`` brought back."""
    copied: list[str] = field(default_factory=list)
    """``cache: false`` outputs copied back from the run cache's copy."""
    from_git: list[str] = field(default_factory=list)
    """``cache: false`` outputs written from the last commit, whose version there is the one ``dvc.lock`` names."""
    missing: list[str] = field(default_factory=list)
    """Outputs absent from the workspace that cannot be brought back: a cached one whose object DVC's cache lacks, a
    ``cache: false`` one whose copy neither the cache nor the last commit holds."""
    stages: dict[str, str] = field(default_factory=dict)
    """The stage of each missing output."""
    why: dict[str, str] = field(default_factory=dict)
    """Why the cache holds no copy of each missing output."""
    committed: set[str] = field(default_factory=set)
    """The missing outputs whose last commit holds another version than ``dvc.lock`` names (the others': none)."""
    checkout_error: str = ""
    """What ``dvc checkout`` refused, if it did (the ``cache: false`` outputs are still brought back)."""


@contextlib.contextmanager
def _quiet_dvc():
    log = logging.getLogger("dvc")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


def _locked_stages(root: Path) -> dict[str, dict]:
    import yaml

    from lfdt.inputs import read_text

    lock = root / "dvc.lock"
    text = read_text(lock, what="DVC's lock file (written by `dvc repro`)")
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise InputError(f"{lock}: not YAML ({first_line(e)})") from None
    if not isinstance(data, dict) or not isinstance(data.get("stages"), dict):
        raise InputError(f"{lock}: expected a `stages:` mapping, as `dvc repro` writes it")
    bad = [name for name, entry in data["stages"].items() if not isinstance(entry, dict)]
    if bad:
        raise InputError(f"{lock}: stage {bad[0]!r} is not a mapping (cmd, deps, outs), as `dvc repro` writes it")
    bad = [name for name, entry in data["stages"].items()
           if not isinstance(entry.get("outs", []), list)
           or not all(isinstance(o, dict) and isinstance(o.get("path"), str) for o in entry.get("outs", []))]
    if bad:
        raise InputError(f"{lock}: the outs of stage {bad[0]!r} are not a list of mappings with a path, as `dvc "
                         f"repro` writes them")
    return data["stages"]


def _message(e: Exception) -> str:
    """DVC's whole message on one line (its first line alone can end in "the following targets:"), with the keys and
    reasons of a schema's refusal (DVC's own message only counts them)."""
    text = " ".join(line.strip() for line in str(e).splitlines() if line.strip())
    errors = getattr(getattr(e, "exc", None), "errors", None) or []
    where = [f"{'.'.join(map(str, getattr(x, 'path', [])))}: {getattr(x, 'msg', x)}" for x in errors[:4]]
    return text + (f" ({'; '.join(where)}{'; ...' if len(errors) > 4 else ''})" if where else "")


def restore(root: str | Path, stages: list[str] | None = None, force: bool = False) -> Restored:
    """Bring back the outputs of ``stages`` (default: every stage of ``dvc.lock``) in the DVC project at ``root``:
    the cached ones by ``dvc checkout`` (``force``: as ``dvc checkout --force``, discarding what a failing stage
    half-wrote into them), the ``cache: false`` ones that are absent by copying them from the local cache by their
    ``dvc.lock`` hash. Existing ``cache: false`` files are never overwritten. Holds DVC's repository lock, so it never
    writes into a stage that a `dvc repro` is running."""
    from dvc.exceptions import DvcException
    from dvc.lock import LockError
    from dvc.repo import Repo, lock_repo

    root = Path(root).resolve()
    locked = _locked_stages(root)
    unknown = [s for s in stages or [] if s not in locked]
    if unknown:
        raise InputError(f"{root / 'dvc.lock'} names no stage {unknown[0]!r} (stages: "
                         f"{', '.join(sorted(locked)[:8])}{', ...' if len(locked) > 8 else ''})")
    names = list(stages) if stages else list(locked)
    done = Restored()
    try:
        repo = Repo(str(root))
    except DvcException as e:
        raise InputError(f"{root}: not a DVC project ({_message(e)})") from None
    with contextlib.chdir(root), repo:  # DVC resolves some paths against the cwd
        try:
            with lock_repo(repo):
                _restore_locked(repo, root, locked, names, stages, force, done)
        except LockError as e:  # a running `dvc repro`
            raise NotRestorable(f"{root}: {_message(e)}") from None
        except DvcException as e:  # a dvc.yaml or dvc.lock DVC's schema refuses
            raise NotRestorable(f"{root}: DVC cannot read the pipeline ({_message(e)})") from None
    return done


def _restore_locked(repo, root: Path, locked: dict, names: list[str], stages: list[str] | None, force: bool,
                    done: Restored) -> None:
    from dvc.exceptions import CheckoutError, DvcException

    index = repo.index.stages
    defined = {s.name for s in index}
    if stages and not set(stages) <= defined:
        raise InputError(f"{root / 'dvc.yaml'} defines no stage {sorted(set(stages) - defined)[0]!r} any more "
                         f"(dvc.lock still names it: `dvc repro` rewrites it)")
    names = [n for n in names if n in defined]  # dvc.lock may still name stages dvc.yaml dropped
    uncached = {(s.name, str(o.def_path)) for s in index for o in s.outs if not o.use_cache}
    kept = {s.name for s in index if all(o.use_cache or o.is_metric or o.is_plot for o in s.outs)}
    cached = [n for n in names if any((n, o["path"]) not in uncached for o in locked[n].get("outs", []))]
    if cached:
        try:
            with _quiet_dvc():
                stats = repo.checkout(targets=cached, force=force)
        except CheckoutError as e:  # outputs whose objects DVC's cache does not hold; the others are checked out
            stats = e.result
            owner = {o["path"]: n for n in cached for o in locked[n].get("outs", [])}
            for path in e.target_infos:
                done.missing.append(path)
                done.stages[path] = owner.get(path, "?")
                done.why[path] = ("a clone without `dvc pull`, `dvc gc` or a cleared cache; `dvc pull` brings it "
                                  "from the project's DVC remote if it has one")
        except DvcException as e:  # a failing stage's half-written files in a cached output
            stats = {}
            done.checkout_error = (f"dvc checkout of {', '.join(cached[:3])}{', ...' if len(cached) > 3 else ''}: "
                                   f"{_message(e)}")
        done.checked_out = sorted(str(p) for p in stats.get("added", []) + stats.get("modified", []))
    cache = repo.stage_cache
    for name in names:
        entry = locked[name]
        wanted = [o["path"] for o in entry.get("outs", []) if (name, o["path"]) in uncached
                  and not (root / o["path"]).exists()]
        if not wanted or "cmd" not in entry:
            continue
        copy = cache._create_stage(entry)  # the run cache's own way back to its uncached outputs
        with cache._cache_type_copy(), _quiet_dvc():
            for out in copy.outs:
                if out.def_path not in wanted:
                    continue
                if out.hash_info and out.cache.exists(out.hash_info.value) and not out.changed_cache():
                    try:
                        out.checkout()
                    except DvcException as e:
                        raise NotRestorable(f"{out.def_path}: DVC's copy could not be checked out "
                                            f"({_message(e)})") from None
                    done.copied.append(out.def_path)
                elif (committed := _from_git(root, out)) is True:
                    done.from_git.append(out.def_path)
                else:
                    done.missing.append(out.def_path)
                    done.stages[out.def_path] = name
                    done.why[out.def_path] = (
                        "DVC's run cache holds none here (a fresh clone, `dvc gc`, `dvc repro --no-commit`)"
                        if name in kept else "DVC keeps none for a stage with plain `cache: false` outputs")
                    if committed is False:
                        done.committed.add(out.def_path)


def _from_git(root: Path, out) -> bool | None:
    """Write the last commit's version of the ``cache: false`` output ``out`` (git's index untouched) and keep it if
    DVC hashes it as ``dvc.lock`` names it: True; False (nothing left written) if the commit holds another version,
    None if it holds none (not committed, not a git repository)."""
    import shutil
    import subprocess

    path = root / str(out.def_path)
    try:
        proc = subprocess.run(["git", "restore", "--source=HEAD", "--worktree", "--", str(out.def_path)], cwd=root,
                              capture_output=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if proc.returncode != 0 or not path.exists():
        return None
    if out.hash_info and not out.changed_checksum():
        return True
    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink()
    return False


def main(argv: list[str] | None = None) -> int:
    """The command line; exit 0 when every output named is back, 2 (one line per output) when some could not be."""
    p = ArgumentParser(prog="python -m lfdt.restore", description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=__doc__.split("\n\n", 1)[1])
    p.add_argument("stages", nargs="*", help="stages as dvc.lock names them (e.g. train_bc@lfdt-50); default all")
    p.add_argument("--root", default=".", help="the DVC project (default the current folder)")
    p.add_argument("--force", action="store_true",
                   help="as `dvc checkout --force`: replace what a failing stage half-wrote into a cached output")
    args = p.parse_args(argv)
    return one_line_errors(lambda: _report(restore(args.root, args.stages, force=args.force), args.force),
                           "what was brought back stays; the same command brings back the rest")


def _report(done: Restored, force: bool) -> int:
    for path in done.checked_out:
        print(f"checked out  {path}")
    for path in done.copied:
        print(f"copied back  {path}  (cache: false; the run cache's copy)")
    for path in done.from_git:
        print(f"from git     {path}  (cache: false; the last commit's copy is the version dvc.lock names)")
    if done.checkout_error:
        hint = "" if force else " (what a failing stage half-wrote: `python -m lfdt.restore --force` replaces it)"
        print(f"error: {done.checkout_error}{hint}", file=sys.stderr)
    for path in done.missing:
        other = path in done.committed
        git = f"`git checkout -- {path}` brings back its last committed version, " if other else ""
        print(f"error: {path}: not in the workspace, and DVC's cache holds no copy of the version dvc.lock names "
              f"({done.why[path]}; the last commit holds {'another version' if other else 'none'}): "
              f"{git}`dvc repro -s {done.stages[path]}` makes it again", file=sys.stderr)
    if not (done.checked_out or done.copied or done.from_git or done.missing or done.checkout_error):
        print("nothing to bring back: every output that dvc.lock names is in the workspace")
    return 2 if done.missing or done.checkout_error else 0


if __name__ == "__main__":
    sys.exit(main())
