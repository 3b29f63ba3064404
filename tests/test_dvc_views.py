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
