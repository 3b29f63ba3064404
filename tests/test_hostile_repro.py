"""Hostile input to `dvc repro`: DVC removes a stage's outputs before it runs the stage, so what can be checked
before any stage runs is checked by the ``preflight`` stage, upstream of every stage that reads params. A bad params
value or tracking URI stops `dvc repro` there, with exit code 2 from the stage, one line naming the key or URI, and
every output of the project in place. A new case is one row of the table. What a stage that fails anyway removed,
the README's commands bring back (:func:`test_what_dvc_removes_comes_back_by_the_readme_command`).
"""

import json
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest
import smoke
import yaml

pytestmark = pytest.mark.xdist_group("smoke_project")  # changes the smoke project's params (and puts them back)


def _outputs(dst: Path) -> dict[str, bytes]:
    """Every file of the Table I policies and of the demonstrations: what a failed repro must leave in place."""
    files = [f for d in ("models/bc", "data/demos") for f in sorted((dst / d).rglob("*")) if f.is_file()]
    assert files
    return {f.relative_to(dst).as_posix(): f.read_bytes() for f in files}


def _set(section: str, **values) -> Callable[[dict], None]:
    return lambda params: params[section].update(values)


@pytest.mark.parametrize(("change", "uri", "says", "args"), [
    (_set("bc", iterations=0), None, "bc.iterations = 0", []),
    (_set("track", gain=0.7), "ftp://tracking.invalid/", "MLFLOW_TRACKING_URI=ftp://tracking.invalid/", []),
    (lambda params: params.pop("bc"), None, "lacks section bc", []),
    (_set("demos", per_pairing=1e29), None, "demos.per_pairing = 1e+29: Input should be a valid integer "
     "(accepted: an integer > 0 and <= 2147483647)", []),
    (lambda params: params.update(device="cuda"), None, "device = 'cuda', but torch", ["-f"]),
], ids=["bad-param", "bad-tracking-uri", "missing-section", "absurd-size", "forced-repro-missing-device"])
def test_a_bad_input_stops_repro_before_any_output_is_removed(smoke_project, monkeypatch, change, uri, says, args):
    """DVC removes a stage's outputs before it runs the stage (`dvc repro -f`: every stage's): the preflight stage,
    upstream of every stage that reads params, fails first on a bad or missing params value, a torch device this
    machine lacks or a bad tracking store, and nothing else runs or loses its outputs. The preflight's own output is
    restored by `dvc checkout` (README, "When a stage fails")."""
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "")  # no CUDA device, even on a machine with one
    dst = smoke_project.root
    original = (dst / "params.yaml").read_text()
    before = _outputs(dst)
    params = yaml.safe_load(original)
    change(params)
    try:
        (dst / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
        out = smoke.dvc(["repro", *args], dst, fails=True, tracking_uri=uri)
    finally:
        (dst / "params.yaml").write_text(original)
    ran = [line.split("'")[1] for line in out.splitlines() if line.startswith("Running stage")]
    assert ran == ["preflight"], out[-2000:]
    assert "exited with 2" in out and says in out, out[-2000:]
    assert _outputs(dst) == before
    smoke.dvc(["checkout", "preflight"], dst)
    assert json.loads(smoke.dvc(["status", "--json"], dst)) == {}


RESTORE = {True: "dvc checkout <stage>", False: "git checkout -- <file>"}
"""The README's command that brings back an output DVC removed, by whether DVC caches it ("When a stage fails")."""


def _files(path: Path) -> dict[str, bytes]:
    return {f.as_posix(): f.read_bytes() for f in ([path] if path.is_file() else sorted(path.rglob("*")))
            if f.is_file()}


def test_what_dvc_removes_comes_back_by_the_readme_command(smoke_project):
    """For every kind of output dvc.yaml has (cached or not, a file or a folder, an output, a metric or a plot,
    persistent or not), one output of that kind, removed as DVC removes it before running its stage, comes back byte
    for byte by the command the README names for it. The project is committed first, as a clone of this repository
    is (the ``cache: false`` files with dvc.lock)."""
    from dvc.repo import Repo

    readme = (smoke.ROOT / "README.md").read_text()
    section = readme[readme.index("**When a stage fails.**"):].split("\n\n", 1)[0]
    assert all(f"`{command}`" in section for command in RESTORE.values()), section
    dst = smoke_project.root
    kinds: dict[tuple, tuple[str, Path]] = {}
    with Repo(str(dst)) as repo:
        for stage in repo.index.stages:
            for out in stage.outs:
                path = dst / str(out.def_path)
                kind = (out.use_cache, bool(out.metric), bool(out.plot), bool(out.persist),
                        path.is_dir() or bool(out.hash_info and out.hash_info.isdir))
                kinds.setdefault(kind, (stage.name, path))  # name: the addressing is relative to the cwd
    assert len(kinds) >= 6, kinds  # at least: cached file and folder; uncached file, folder, metric and plot
    uncached = [path for (cached, *_), (_, path) in kinds.items() if not cached]
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t"]
    committed = ["dvc.lock", *map(str, uncached)]
    subprocess.run([*git, "add", "-f", "--", *committed], cwd=dst, check=True)
    subprocess.run([*git, "commit", "-qm", "outputs as committed", "--allow-empty", "--", *committed], cwd=dst,
                   check=True)
    before = {kind: _files(path) for kind, (_, path) in kinds.items()}
    for _, path in kinds.values():
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink()
    for kind, (stage, path) in kinds.items():
        command = RESTORE[kind[0]].replace("<stage>", stage).replace("<file>", str(path.relative_to(dst)))
        if command.startswith("dvc "):
            smoke.dvc(command.split()[1:], dst)
        else:
            subprocess.run(command.split(), cwd=dst, check=True)
    lost = [path for kind, (_, path) in kinds.items() if _files(path) != before[kind]]
    assert not lost, f"not brought back byte for byte by the README's command: {lost}"
