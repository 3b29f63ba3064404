import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before any test loads numpy or torch)

import os
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


@pytest.fixture(scope="session")
def smoke_project(tmp_path_factory) -> SmokeProject:
    """A copy of the project with the smoke params, after one full `dvc repro` (shared by the smoke and sweep
    tests: the sweep must give the same tables)."""
    import smoke

    dst = smoke.make_project(tmp_path_factory.mktemp("smoke"))
    out = smoke.dvc(["repro"], dst, timeout=smoke.REPRO_TIMEOUT_S)
    return SmokeProject(dst, out, {t: (dst / t).read_bytes() for t in smoke.TABLES})
