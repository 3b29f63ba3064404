"""Hostile input to `dvc repro`: DVC removes a stage's outputs before it runs the stage, so what can be checked
before any stage runs is checked by the ``preflight`` stage, upstream of every stage that reads params. A bad params
value or tracking URI stops `dvc repro` there, with exit code 2 from the stage, one line naming the key or URI, and
every output of the project in place. A new case is one row of the table.
"""

import json
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


@pytest.mark.parametrize(("change", "uri", "says"), [
    ({"bc": {"iterations": 0}}, None, "bc.iterations = 0"),
    ({"track": {"gain": 0.7}}, "ftp://tracking.invalid/", "MLFLOW_TRACKING_URI=ftp://tracking.invalid/"),
], ids=["bad-param", "bad-tracking-uri"])
def test_a_bad_input_stops_repro_before_any_output_is_removed(smoke_project, change, uri, says):
    """DVC removes a stage's outputs before it runs the stage: the preflight stage, upstream of every stage that reads
    params, fails first on a bad params value or tracking store, and nothing else runs or loses its outputs. The
    preflight's own output is restored by `dvc checkout` (README, "When a stage fails")."""
    dst = smoke_project.root
    original = (dst / "params.yaml").read_text()
    before = _outputs(dst)
    params = yaml.safe_load(original)
    for section, values in change.items():
        params[section].update(values)
    try:
        (dst / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
        out = smoke.dvc(["repro"], dst, fails=True, tracking_uri=uri)
    finally:
        (dst / "params.yaml").write_text(original)
    ran = [line.split("'")[1] for line in out.splitlines() if line.startswith("Running stage")]
    assert ran == ["preflight"], out[-2000:]
    assert "exited with 2" in out and says in out, out[-2000:]
    assert _outputs(dst) == before
    smoke.dvc(["checkout", "preflight"], dst)
    assert json.loads(smoke.dvc(["status", "--json"], dst)) == {}

