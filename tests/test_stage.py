"""The helpers every stage script shares."""

import csv

from lfdt import stage


def test_write_csv_takes_the_union_of_the_rows_columns(tmp_path):
    # a translator curve: diagnostics every log_every iterations, held-out losses every select_every
    rows = [{"iteration": 200, "loss/D": 0.7}, {"iteration": 500, "heldout/dyn": 0.3},
            {"iteration": 600, "loss/D": 0.6}]
    path = stage.write_csv(tmp_path / "curve.csv", rows)
    with open(path) as fh:
        got = list(csv.reader(fh))
    assert got == [["iteration", "loss/D", "heldout/dyn"], ["200", "0.7", ""], ["500", "", "0.3"], ["600", "0.6", ""]]
    assert not list(tmp_path.glob(".*tmp*"))


def test_write_json_is_atomic_and_readable(tmp_path):
    import json

    path = stage.write_json(tmp_path / "sub" / "m.json", {"a": 1})
    assert json.loads(path.read_text()) == {"a": 1} and not list(path.parent.glob(".*tmp*"))
