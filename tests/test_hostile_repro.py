"""Hostile input to `dvc repro`: DVC removes a stage's outputs before it runs the stage, so what can be checked
before any stage runs is checked by the ``preflight`` stage, upstream of every stage that reads params. A bad params
value or tracking URI stops `dvc repro` there, with exit code 2 from the stage, one line naming the key or URI, and
every output of the project in place. A new case is one row of the table. What a stage that fails anyway removed,
the README's commands bring back (:func:`test_what_dvc_removes_comes_back_by_the_readme_command`).
"""

import json
import shutil
import subprocess
import sys
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
    (lambda params: params["bc"].pop("iterations"), None, "lacks bc.iterations (default 8000)", []),
    (_set("twin", tasks=["block_push", "peg_insert"]), None, "twin.tasks: unknown task(s) ['peg_insert']", []),
], ids=["bad-param", "bad-tracking-uri", "missing-section", "absurd-size", "forced-repro-missing-device",
        "deleted-key", "unknown-twin-task"])
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


RESTORE = "python -m lfdt.restore"
"""The README's command that brings back what DVC removed, every kind of output ("When a stage fails")."""


def _files(path: Path) -> dict[str, bytes]:
    return {f.as_posix(): f.read_bytes() for f in ([path] if path.is_file() else sorted(path.rglob("*")))
            if f.is_file()}


def _restore(dst: Path, *stages: str, fails: bool = False) -> str:
    proc = subprocess.run([sys.executable, "-m", "lfdt.restore", *stages], cwd=dst, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == (2 if fails else 0), f"{RESTORE} {' '.join(stages)}: exit {proc.returncode}\n" \
                                                   f"{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    return proc.stdout + proc.stderr


def _readme_section() -> str:
    readme = (smoke.ROOT / "README.md").read_text()
    return readme[readme.index("**When a stage fails.**"):].split("\n\n", 1)[0]


def _kept_by_dvc(stage) -> bool:
    """Whether DVC's run cache keeps a copy of the stage's ``cache: false`` outputs: only where all are metrics or
    plots (DVC's Stage.run)."""
    return all(o.use_cache or o.is_metric or o.is_plot for o in stage.outs)


def test_what_dvc_removes_comes_back_by_the_readme_command(smoke_project):
    """For every kind of output dvc.yaml has (cached or not, a file or a folder, an output, a metric or a plot,
    persistent or not, of a stage DVC's run cache keeps or not), one output of that kind, removed as DVC removes it
    before running its stage, comes back byte for byte by the README's command: from DVC's cache, from the run
    cache's copy (never committed to git), or, for a stage DVC keeps no copy of, from the last commit when that holds
    the version dvc.lock names. Where the commit holds another version, the output is named (exit 2) with `git
    checkout -- <file>`, and nothing is left written in its place."""
    from dvc.repo import Repo

    assert f"`{RESTORE} <stage>`" in _readme_section() and "`git checkout -- <file>`" in _readme_section()
    dst = smoke_project.root
    kinds: dict[tuple, tuple[str, Path]] = {}
    with Repo(str(dst)) as repo:
        for stage in repo.index.stages:
            for out in stage.outs:
                path = dst / str(out.def_path)
                kind = (out.use_cache or _kept_by_dvc(stage), out.use_cache, bool(out.metric), bool(out.plot),
                        bool(out.persist), path.is_dir() or bool(out.hash_info and out.hash_info.isdir))
                kinds.setdefault(kind, (stage.name, path))  # name: addressing is relative to the cwd
    assert len(kinds) >= 8, kinds  # cached file and folder; uncached metric and plot, kept or not; plain file, folder
    assert {k[0] for k in kinds if not k[1]} == {True, False}, kinds
    paths = {kind: path for kind, (_, path) in kinds.items()}
    rel = {kind: str(path.relative_to(dst)) for kind, path in paths.items()}
    tracked = subprocess.run(["git", "ls-files", "--", *rel.values()], cwd=dst, capture_output=True, text=True,
                             check=True).stdout.split()
    assert not tracked, f"committed to git, so this test would not show they come back without it: {tracked}"
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t"]
    committed = ["dvc.lock", *(rel[k] for k in kinds if not k[0])]
    subprocess.run([*git, "add", "-f", "--", *committed], cwd=dst, check=True)
    subprocess.run([*git, "commit", "-qm", "what DVC keeps no copy of", "--", *committed], cwd=dst, check=True)
    before = {kind: _files(path) for kind, path in paths.items()}
    stages = sorted({stage for stage, _ in kinds.values()})

    def remove() -> None:
        for path in paths.values():
            if path.is_dir():
                shutil.rmtree(path)
            else:
                path.unlink()

    remove()
    out = _restore(dst, *stages)
    lost = [rel[k] for k in kinds if _files(paths[k]) != before[k]]
    assert not lost, f"not brought back byte for byte by `{RESTORE}`: {lost}\n{out}"
    assert {line.split()[2] for line in out.splitlines() if line.startswith("from git")} == \
        {rel[k] for k in kinds if not k[0]}, out
    assert subprocess.run(["git", "status", "--porcelain", "--", *committed], cwd=dst, capture_output=True,
                          text=True, check=True).stdout == "", "restore changed git's index or the files"

    file = next(k for k in kinds if not k[0] and not k[5])  # a committed file: commit another version of it
    paths[file].write_bytes(before[file][paths[file].as_posix()] + b"edited by hand\n")
    subprocess.run([*git, "commit", "-qm", "another version", "--", rel[file]], cwd=dst, check=True)
    try:
        remove()
        out = _restore(dst, *stages, fails=True)
        named = {line.split(":")[1].strip() for line in out.splitlines() if line.startswith("error: ")}
        assert named == {rel[file]}, out
        assert f"`git checkout -- {rel[file]}`" in out and "the last commit holds another version" in out, out
        assert not paths[file].exists(), "the commit's other version was left in the workspace"
        lost = [rel[k] for k in kinds if k != file and _files(paths[k]) != before[k]]
        assert not lost, f"not brought back byte for byte by `{RESTORE}`: {lost}\n{out}"
    finally:  # the version dvc.lock names, committed again
        paths[file].write_bytes(before[file][paths[file].as_posix()])
        subprocess.run([*git, "commit", "-qm", "the version dvc.lock names", "--", rel[file]], cwd=dst, check=True)


def test_a_failing_stage_s_outputs_come_back_and_a_newer_file_stays(smoke_project):
    """A real failure: `dvc repro -f -s fit_dynamics` with a tracking server that does not answer stops with a named
    error after DVC removed the stage's outputs (its models, a folder DVC caches; its curve, a ``cache: false`` plot).
    With a file half-written into the models folder (a stage that fails partway), the README's command brings the
    curve back, names that file and ``--force`` (exit 2) and leaves it; with ``--force`` everything is back byte for
    byte (the curve was never committed to git), DVC sees the stage up to date, and a second call finds nothing.
    A ``cache: false`` file that is in the workspace is never overwritten (it may be newer than dvc.lock)."""
    dst = smoke_project.root
    models, curve = dst / "models/dynamics", dst / "reports/dynamics_curve.csv"
    before = {p: _files(p) for p in (models, curve)}
    assert all(before.values())
    failed = smoke.dvc(["repro", "-f", "-s", "fit_dynamics"], dst, fails=True, tracking_uri="http://127.0.0.1:9")
    assert "error:" in failed and "127.0.0.1:9" in failed, failed[-2000:]
    assert not models.exists() and not curve.exists(), "DVC kept the outputs of the failing stage: this test shows " \
                                                       "nothing"
    half = models / "half-written.pt"  # what a stage that fails partway through leaves in a cached output
    half.parent.mkdir(parents=True, exist_ok=True)
    half.write_bytes(b"partial")
    out = _restore(dst, "fit_dynamics", fails=True)
    assert "copied back  reports/dynamics_curve.csv" in out and _files(curve) == before[curve], out
    assert "half-written.pt" in out and "`python -m lfdt.restore --force`" in out, out
    assert half.exists(), "restore without --force removed a file it was not asked to"
    out = _restore(dst, "--force", "fit_dynamics")
    assert {p: _files(p) for p in (models, curve)} == before, out
    assert "up to date" in smoke.dvc(["status", "fit_dynamics"], dst)
    assert _restore(dst, "fit_dynamics").startswith("nothing to bring back"), "a second call did something"
    curve.write_text("newer than dvc.lock\n")
    try:
        assert _restore(dst, "fit_dynamics").startswith("nothing to bring back")
        assert curve.read_text() == "newer than dvc.lock\n"
    finally:
        curve.write_bytes(before[curve][curve.as_posix()])


def test_restore_names_a_stage_dvc_lock_or_dvc_yaml_does_not_have(smoke_project, tmp_path):
    """A stage that dvc.lock does not name is one line naming it, exit 2; so is one that dvc.lock names but
    dvc.yaml no longer defines, and without a stage such a leftover of dvc.lock is passed over."""
    out = _restore(smoke_project.root, "no_such_stage", fails=True)
    assert out.count("\n") == 1 and "dvc.lock names no stage 'no_such_stage'" in out, out
    dst = tmp_path / "p"
    subprocess.run(["git", "init", "-q", str(dst)], check=True)
    (dst / ".dvc").mkdir()
    (dst / ".dvc/config").write_text("")
    (dst / "dvc.yaml").write_text("stages: {}\n")
    (dst / "dvc.lock").write_text("schema: '2.0'\nstages: {gone: {cmd: x, outs: [{path: a.txt, hash: md5, "
                                  "md5: 0123456789abcdef0123456789abcdef, size: 3}]}}\n")  # as `dvc repro` writes it
    out = _restore(dst, "gone", fails=True)
    assert out.count("\n") == 1 and "dvc.yaml defines no stage 'gone' any more" in out, out
    assert _restore(dst).startswith("nothing to bring back")


@pytest.mark.parametrize(("lock", "dvc_project", "says"), [
    (None, True, "dvc.lock: no such file"),
    ("stages: [1\n", True, "dvc.lock: not YAML"),
    ("schema: '2.0'\nstages: {a: 5}\n", True, "dvc.lock: stage 'a' is not a mapping"),
    ("schema: '2.0'\nstages: {a: {cmd: x, outs: [5]}}\n", True, "dvc.lock: the outs of stage 'a' are not a list"),
    ("schema: 2.0\nstages: {a: {cmd: x, outs: [{path: a.txt, md5: '01'}]}}\n", True,
     ": DVC cannot read the pipeline ('./dvc.lock' validation failed: 2 errors (schema: invalid schema version; "
     "stages.a.outs.0.md5: not a valid value))"),
    ("schema: '2.0'\nstages: {}\n", False, ": not a DVC project"),
], ids=["no-lock", "lock-not-yaml", "stage-not-a-mapping", "outs-not-mappings", "schema-dvc-refuses",
        "not-a-dvc-project"])
def test_restore_refuses_a_hostile_project_in_one_line(tmp_path, lock, dvc_project, says):
    """The README's restore command on a project it cannot read: one line naming the file or folder, exit 2."""
    if dvc_project:
        subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
        (tmp_path / ".dvc").mkdir()
        (tmp_path / ".dvc/config").write_text("")
        (tmp_path / "dvc.yaml").write_text("stages: {}\n")
    if lock is not None:
        (tmp_path / "dvc.lock").write_text(lock)
    proc = subprocess.run([sys.executable, "-m", "lfdt.restore", "--root", str(tmp_path)], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2 and not proc.stdout, proc.stdout + proc.stderr
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("error: ") and says in proc.stderr, proc.stderr
    assert str(tmp_path) in proc.stderr, proc.stderr


def test_restore_waits_for_no_running_repro(tmp_path):
    """While a `dvc repro` holds DVC's repository lock, restore writes nothing: one line naming the folder and the
    lock, exit 2."""
    from dvc.repo import Repo, lock_repo

    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    (tmp_path / ".dvc").mkdir()
    (tmp_path / ".dvc/config").write_text("")
    (tmp_path / "dvc.yaml").write_text("stages: {}\n")
    (tmp_path / "dvc.lock").write_text("schema: '2.0'\nstages: {}\n")
    with Repo(str(tmp_path)) as repo, lock_repo(repo):
        proc = subprocess.run([sys.executable, "-m", "lfdt.restore", "--root", str(tmp_path)], capture_output=True,
                              text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2 and not proc.stdout, proc.stdout + proc.stderr
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith(f"error: {tmp_path}: Unable to acquire lock"), \
        proc.stderr


def test_restore_names_a_cached_output_dvc_s_cache_lacks(tmp_path):
    """A cached output whose object DVC's cache no longer holds (a clone without `dvc pull`, `dvc gc`): restore brings
    back the others and names it in one line, with `dvc pull` and the stage to rerun; exit 2. Before, DVC's "Is your
    cache up to date?" came with advice to use ``--force``, which cannot help."""
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    smoke.dvc(["init", "-q"], tmp_path)
    write = ("import pathlib, sys; pathlib.Path(sys.argv[1]).mkdir(); "
             "pathlib.Path(sys.argv[1], 'a.txt').write_text(sys.argv[1])")
    (tmp_path / "dvc.yaml").write_text(yaml.safe_dump({"stages": {
        name: {"cmd": f'python -c "{write}" {name}', "outs": [name]} for name in ("kept", "gone")}}))
    smoke.dvc(["repro", "-q"], tmp_path)
    gone_hash = yaml.safe_load((tmp_path / "dvc.lock").read_text())["stages"]["gone"]["outs"][0]["md5"]
    for name in ("kept", "gone"):
        shutil.rmtree(tmp_path / name)
    (tmp_path / ".dvc/cache/files/md5" / gone_hash[:2] / gone_hash[2:]).unlink()
    proc = subprocess.run([sys.executable, "-m", "lfdt.restore", "--root", str(tmp_path)], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert (tmp_path / "kept/a.txt").read_text() == "kept" and "checked out  kept" in proc.stdout, proc.stdout
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("error: gone: not in the workspace"), proc.stderr
    assert "`dvc pull`" in proc.stderr and "`dvc repro -s gone`" in proc.stderr, proc.stderr
    assert "--force" not in proc.stderr, proc.stderr
