"""DVC's run cache through a shared remote: what a chain publishes and what the coordinator restores from.

``dvc push --run-cache`` sends the run records but only the objects that the workspace's ``dvc.lock`` names, and a
chain's clone has no lock for the sweep's params; it never sends the metrics and plots files (``cache: false``)
that DVC keeps beside each record. :func:`publish` sends every object the local run records name, then the
records, so a record never reaches the remote before the objects it needs: a chain killed half-way leaves nothing
that a restore would trust.
"""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path

from lfdt.errors import StageError


class PublishError(StageError):
    """Objects of a run record could not be sent to the remote."""


@contextlib.contextmanager
def _quiet_dvc():
    log = logging.getLogger("dvc")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


def _entries(repo) -> list[tuple[str, str]]:
    runs = Path(repo.cache.legacy.path) / "runs"
    return [(p.parent.name, p.name) for p in sorted(runs.glob("*/*/*")) if p.is_file()]


def fetch(root: str | Path, remote: str) -> int:
    """Copy the remote's run records (not their objects: ``dvc repro --pull`` fetches those it restores) into the
    project at ``root``; returns how many were new."""
    from dvc.repo import Repo

    with contextlib.chdir(root), Repo(str(root)) as repo:  # DVC resolves some paths against the cwd
        return len(repo.stage_cache.pull(remote))


def publish(root: str | Path, remote: str) -> int:
    """Send to ``remote`` every run record of the project at ``root`` whose objects are all in its cache, objects
    first; returns how many records. Records fetched from the remote (their objects stay there) are left out."""
    from dvc.exceptions import CollectCacheError
    from dvc.repo import Repo

    with contextlib.chdir(root), Repo(str(root)) as repo:  # DVC resolves some paths against the cwd
        local = repo.cache.local
        ready, objs = [], set()
        for entry in _entries(repo):
            try:
                with _quiet_dvc():  # a record whose objects this cache lacks is skipped, not worth a warning
                    used = repo.stage_cache.get_used_objs([entry])
            except CollectCacheError:
                continue
            hashes = {h for hs in used.values() for h in hs}
            if all(local.exists(h.value) for h in hashes):
                ready.append(entry)
                objs |= hashes
        result = repo.cloud.push(objs, remote=remote)
        if result.failed:
            raise PublishError(f"{len(result.failed)} objects of {root} could not be sent to the DVC remote "
                               f"{remote!r} (first: {sorted(str(h) for h in result.failed)[0]})")
        odb = repo.cloud.get_remote_odb(remote, "push --run-cache", hash_name="md5-dos2unix")
        runs = Path(repo.cache.legacy.path) / "runs"
        for key, value in ready:
            parent = odb.fs.join(odb.path, "runs", key[:2], key)
            odb.fs.makedirs(parent, exist_ok=True)
            odb.fs.put_file(str(runs / key[:2] / key / value), odb.fs.join(parent, value))
        return len(ready)
