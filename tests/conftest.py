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
    # The timeout guards against a hang, never a speed: the smoke DAG takes about 4 minutes on a 2-core EPYC and
    # went past 10 on a slower 2-core Xeon with the other pytest worker busy (CI of 2026-12-01).
    out = smoke.dvc(["repro"], dst, timeout=smoke.REPRO_TIMEOUT_S)
    return SmokeProject(dst, out, {t: (dst / t).read_bytes() for t in smoke.TABLES})
