"""The `dvc exp show` filters of docs/pipeline.md, run on the committed results: each shows its slice of Table I's
headline metrics and fits in 200 columns."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _readme_filters() -> list[str]:
    """The filters of the "DVC views" section of docs/pipeline.md."""
    text = (ROOT / "docs" / "pipeline.md").read_text()
    section = text[text.index("## DVC views"):]
    section = section[:section.index("\n#", 1)]
    filters = re.findall(r"^dvc exp show --drop '\.\*' --keep '([^']+)'", section, re.M)
    assert len(filters) >= 2, "docs/pipeline.md gives no `dvc exp show` filter"
    return filters


@pytest.mark.parametrize("keep", _readme_filters())
def test_exp_show_filter_fits_in_200_columns(keep):
    headline = json.loads((ROOT / "reports/table1.json").read_text())
    env = {**os.environ, "COLUMNS": "200", "DVC_NO_ANALYTICS": "1",
           "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    out = subprocess.run([sys.executable, "-m", "dvc", "exp", "show", "--no-pager", "--drop", ".*", "--keep", keep],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert max(len(line) for line in lines) <= 200, out.stdout
    header = lines[1]
    want = [f"{m}.{d}" for m, row in headline.items() for d in row if re.match(keep, f"{m}.{d}")]
    assert len(want) >= 3
    for col in want:
        assert re.search(rf"(?<![\w.]){re.escape(col)}(?![\w.])", header), f"{col} missing from:\n{out.stdout}"


def _dvc_json(*args: str) -> dict:
    env = {**os.environ, "DVC_NO_ANALYTICS": "1", "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    out = subprocess.run([sys.executable, "-m", "dvc", *args, "--json"], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def _values(x) -> int:
    if isinstance(x, dict):
        return sum(_values(v) for v in x.values())
    if isinstance(x, list):
        return sum(_values(v) for v in x)
    return 1


def test_metrics_show_lists_one_headline_file_per_report():
    """`dvc metrics show` gives Table I, the twin's rates and the experts: nothing per configuration, <= 80 values."""
    shown = _dvc_json("metrics", "show")
    files = {f: m.get("data", {}) for rev in shown.values() for f, m in rev["data"].items()}
    assert set(files) == {"reports/table1.json", "reports/twin.json", "reports/experts.json"}, sorted(files)
    assert _values(files) <= 80, f"dvc metrics show lists {_values(files)} values"
    twin = files["reports/twin.json"]
    assert {m for t in twin.values() for m in t} == {"lfdt", "bc_no_translation"}
    assert all(0 <= v["ci_low"] <= v["success_rate"] <= v["ci_high"] <= 1 for t in twin.values() for v in t.values())


def test_plots_show_draws_at_most_12_charts():
    plots = _dvc_json("plots", "show", "--split")
    charts = plots.get("data", plots)
    assert 0 < len(charts) <= 12, f"dvc plots show draws {len(charts)} charts: {sorted(charts)}"
