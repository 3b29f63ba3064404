import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before any test loads numpy or torch)

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")


_UNGROUPED: set[str] = set()
"""Tests of an ``xdist_group`` that pytest-xdist did not tag with their group (see the hook below)."""


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items) -> None:
    """Under `pytest -n N --dist loadgroup` (make test), note the tests of an ``xdist_group`` that pytest-xdist left
    untagged: the group then spreads over the workers and each of them builds the smoke DAG at once (pytest 9.2 with
    xdist 3.8 did this silently, two builds fighting for two cores)."""
    if os.environ.get("PYTEST_XDIST_WORKER") and config.getvalue("loadgroup"):
        _UNGROUPED.update(item.nodeid for item in items if item.get_closest_marker("xdist_group") is not None
                          and "@" not in item.nodeid.rsplit("::", 1)[-1])


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item) -> None:
    """Fail an untagged grouped test before its fixtures build anything, saying why."""
    if item.nodeid in _UNGROUPED:
        pytest.fail("pytest-xdist's loadgroup did not tag this test with its xdist_group, so the group's shared "
                    "fixtures would be built on every worker: this pytest and pytest-xdist do not work together; "
                    "install requirements.txt's pins", pytrace=False)


@dataclass
class SmokeProject:
    root: Path
    output: str
    """What the first `dvc repro` printed."""
    tables: dict[str, bytes]
    """The reports of :data:`smoke.TABLES` right after it (later tests change the project's params)."""


def _build_smoke_project(tmp_path_factory) -> SmokeProject:
    """Build the smoke project once per test session, whichever worker asks first; the others wait for it and get
    the same project. Under `pytest -n` the workers' temporary folders share a parent, where the build lives beside
    a lock and a marker written last (the xdist documentation's pattern for a session-wide fixture)."""
    import smoke
    from filelock import FileLock

    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    root, tables = shared / "smoke", shared / "smoke-tables"
    done = shared / "smoke-built"
    with FileLock(str(shared / "smoke.lock"), timeout=smoke.REPRO_TIMEOUT_S + 600):
        if not done.exists():
            if root.exists():
                pytest.fail(f"the smoke project's `dvc repro` failed in {root} (see the test that built it)")
            smoke.make_project(root)
            out = smoke.run_quick_start(root)  # the README's `make reproduce`: dvc repro on the smoke params
            tables.mkdir()
            for i, t in enumerate(smoke.TABLES):
                (tables / str(i)).write_bytes((root / t).read_bytes())
            (shared / "smoke-output.txt").write_text(out)
            done.touch()
    saved = {t: (tables / str(i)).read_bytes() for i, t in enumerate(smoke.TABLES)}
    return SmokeProject(root, (shared / "smoke-output.txt").read_text(), saved)


@pytest.fixture(scope="session")
def smoke_project(tmp_path_factory) -> SmokeProject:
    """A copy of the project with the smoke params, after one full `dvc repro`, for the tests that look at or change
    it (they run on one worker: their ``xdist_group``)."""
    return _build_smoke_project(tmp_path_factory)


@pytest.fixture(scope="session")
def smoke_tables(tmp_path_factory) -> Callable[[], dict[str, bytes]]:
    """The smoke project's tables right after its `dvc repro`, fetched when called: the sweep tests run their own DAG
    on the other worker meanwhile and ask only at the end (built here if no other worker builds it)."""
    return lambda: _build_smoke_project(tmp_path_factory).tables


def pytest_terminal_summary(terminalreporter) -> None:
    """Name the CPU the tests ran on, with the numeric mode: where tests/test_fingerprint.py passed, that CPU computes
    the committed fingerprint's bits (a CI log then says which CPUs reproduce it)."""
    from lfdt import numerics

    d = numerics.describe()
    terminalreporter.write_line(f"CPU: {d['cpu_model']} ({d['cpu_isa']}), numerics {d['numerics']}")
