import os
from dataclasses import dataclass
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")


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
    out = smoke.dvc(["repro"], dst)
    return SmokeProject(dst, out, {t: (dst / t).read_bytes() for t in smoke.TABLES})
