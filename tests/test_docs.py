"""Every number the README and docs/ take from reports/ or benchmarks/results/ is what those files say now."""

import lfdt.numerics  # noqa: F401

from collections.abc import Callable
from pathlib import Path

import pytest

from lfdt import docs
from lfdt.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


def test_every_generated_block_agrees_with_its_reports():
    bad = docs.stale()
    assert not bad, f"pages disagree with their reports (run `make docs`): {bad}"


def test_a_block_that_disagrees_is_named(tmp_path: Path):
    (tmp_path / "reports").mkdir()
    (tmp_path / "reports" / "table1.md").write_text("| a |\n")
    page = tmp_path / "README.md"
    page.write_text("x\n<!-- generated:table1 -->\n| old |\n<!-- /generated:table1 -->\n")
    assert docs.stale(tmp_path) == ["README.md: table1"]
    page.write_text(docs.render_page(page.read_text(), tmp_path))
    assert docs.stale(tmp_path) == [] and "| a |" in page.read_text()


def test_an_unknown_block_is_an_error():
    with pytest.raises(InputError, match="unknown generated block 'nope'"):
        docs.render_page("<!-- generated:nope -->\n<!-- /generated:nope -->\n")


def test_a_search_block_pairs_its_best_trial_with_its_baseline(tmp_path: Path):
    """The search block (tools/dev_search.py's studies) lists every trial and pairs the best with trial 0 over the
    same seeds and start states."""
    exp = tmp_path / "docs" / "experiments"
    (exp / "outcomes").mkdir(parents=True)
    fields = ["date", "trial", "method", "demos", "seeds", "cpu_model", "numerics"]
    rows = [["2026-12-06", f"st-search-x-t{n}", "lfdt", "50", "40 41", "Some CPU", "pinned"] for n in (0, 1)]
    (exp / "trials.csv").write_text("\n".join(",".join(r) for r in [fields, *rows]) + "\n")
    outcomes = {0: {40: "1100", 41: "1000"}, 1: {40: "1110", 41: "1100"}}
    for n, by_seed in outcomes.items():
        (exp / "outcomes" / f"st-search-x-t{n}_lfdt-d50.csv").write_text(
            "seed,outcomes\n" + "".join(f"{s},{o}\n" for s, o in by_seed.items()))
    knobs = ["translator.lambda_dyn", "translator.lambda_side"]
    (exp / "search_st-search-x.csv").write_text(
        "trial," + ",".join(knobs) + ",success_pct,worst_seed_pct,per_seed_pct,path_success_pct,path_worst_seed_pct,"
        "wall_min\n0,10.0,0.0,37.5,25.0,50.0 25.0,37.5,25.0,4.1\n1,3.0,10.0,62.5,50.0,75.0 50.0,62.5,50.0,4.3\n")
    block = docs.search(tmp_path)
    assert "| t0 (params.yaml) | 10.0 | 0.0 | 37.5 % (25.0 %) |" in block, block
    assert "Best of 2 trials: t1, 62.5 %" in block and "+25.0 points" in block, block
    assert "development seeds 40 41" in block and "Some CPU (pinned), 2026-12-06 to 2026-12-06" in block, block
    table = (exp / "search_st-search-x.csv").read_text().splitlines()
    (exp / "search_st-search-x.csv").write_text("\n".join(
        [table[0].replace("trial,", "trial,baseline,", 1)] +
        [line.replace(",", f",{line.startswith('0,')},", 1) for line in table[1:]]) + "\n")
    assert docs.search(tmp_path) == block  # the table's baseline column (tools/dev_search.py) names the same row


def test_a_confirmation_block_pairs_candidate_and_baseline_by_both_rules(tmp_path: Path, monkeypatch):
    """The confirmation block: each pair that ran, both success rules, the paired difference over the same seeds
    and start states; a pair whose trials have not run is left out."""
    exp = tmp_path / "docs" / "experiments"
    (exp / "outcomes").mkdir(parents=True)
    fields = ["date", "trial", "method", "demos", "seeds", "cpu_model", "numerics", "changes", "success_pct",
              "worst_seed_pct"]
    rows = [["2026-12-06", "c", "lfdt", "50", "45 46", "Some CPU", "pinned", "translator.lambda_dyn=3.0", "75.0",
             "50.0"],
            ["2026-12-06", "b", "lfdt", "50", "45 46", "Some CPU", "pinned", "", "37.5", "25.0"]]
    (exp / "trials.csv").write_text("\n".join(",".join(r) for r in [fields, *rows]) + "\n")
    outcomes = {("c", ""): {45: "1110", 46: "1100"}, ("b", ""): {45: "1100", 46: "1000"},
                ("c", "_path"): {45: "1100", 46: "1100"}, ("b", "_path"): {45: "1100", 46: "1100"}}
    for (t, suffix), by_seed in outcomes.items():
        (exp / "outcomes" / f"{t}_lfdt-d50{suffix}.csv").write_text(
            "seed,outcomes\n" + "".join(f"{s},{o}\n" for s, o in by_seed.items()))
    monkeypatch.setattr(docs, "CONFIRMATIONS", (("c", "b"), ("never-ran", "b")))
    block = docs.confirm(tmp_path)
    assert "| c (translator.lambda_dyn=3.0) | b (params.yaml) | 50 | 45 46 | 75.0 % (50.0 %) | 37.5 % (25.0 %) | " \
           "+25.0 (" in block, block
    assert block.count("\n| ") == 2 and "| +0.0 (" in block and "Some CPU (pinned)" in block, block


# -------------------------------------------------------------------------------- reports that are not what they were

PAGE = ("x\n<!-- generated:headline -->\nold\n<!-- /generated:headline -->\n"
        "<!-- generated:run_time -->\nold\n<!-- /generated:run_time -->\n")
"""A page with the blocks of reports/table1.csv, run_time.json and stage_times.csv."""
TABLE1 = "reports/table1.csv"


def _cut(name: str, keep: float) -> Callable[[Path], None]:
    def damage(root: Path) -> None:
        data = (root / name).read_bytes()
        (root / name).write_bytes(data[:int(len(data) * keep)])
    return damage


def _replace(name: str, old: str, new: str) -> Callable[[Path], None]:
    def damage(root: Path) -> None:
        text = (root / name).read_text()
        assert old in text, old
        (root / name).write_text(text.replace(old, new, 1))
    return damage


HOSTILE_REPORTS = [
    # (id, what is done to the reports, what the one line must say)
    ("missing", lambda root: (root / TABLE1).unlink(), "report {root}/reports/table1.csv: no such file"),
    ("empty", lambda root: (root / TABLE1).write_text(""), "report {root}/reports/table1.csv: has no header line"),
    ("cut-mid-row", _cut(TABLE1, 0.5), "report {root}/reports/table1.csv, line "),
    ("header-only", lambda root: (root / "reports/stage_times.csv").write_text("stage,runs,total_s,mean_s\n"),
     "report {root}/reports/stage_times.csv: holds a header and no rows"),
    ("column-renamed", _replace(TABLE1, "success_rate,", "succ_rate,"), "its header has no column 'success_rate'"),
    ("text-for-a-number", _replace(TABLE1, "\nlfdt,50,", "\nlfdt,fifty,"),
     "generated block 'headline': its reports do not hold what it reads (ValueError"),
    ("not-utf8", lambda root: (root / TABLE1).write_bytes(b"method,\xffdemos\n"), "line 1: byte 0xff"),
    ("json-cut", _cut("reports/run_time.json", 0.5), "report {root}/reports/run_time.json: is not JSON"),
    ("json-a-list", lambda root: (root / "reports/run_time.json").write_text("[]"), "holds a JSON list, not an object"),
]


@pytest.mark.parametrize(("damage", "says"), [c[1:] for c in HOSTILE_REPORTS], ids=[c[0] for c in HOSTILE_REPORTS])
def test_a_damaged_report_is_one_named_error_and_no_page_changes(tmp_path: Path, damage, says, capsys):
    """`make docs` after a run cut short or a report edited by hand: exit 2, one line naming the report, the page
    left as it was (never a partial table)."""
    (tmp_path / "reports").mkdir()
    for name in (TABLE1, "reports/run_time.json", "reports/stage_times.csv"):
        (tmp_path / name).write_bytes((ROOT / name).read_bytes())
    (tmp_path / "README.md").write_text(PAGE)
    assert docs.main([], root=tmp_path) == 0 and "old" not in (tmp_path / "README.md").read_text()
    (tmp_path / "README.md").write_text(PAGE)
    capsys.readouterr()
    damage(tmp_path)
    assert docs.main([], root=tmp_path) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and says.format(root=tmp_path) in err[0], err
    assert (tmp_path / "README.md").read_text() == PAGE


def test_a_cross_cpu_report_without_emulated_cpus_names_no_qemu(tmp_path: Path):
    """`tools/cross_cpu.py --models` with none (this CPU only, on a machine without QEMU) writes no QEMU version: the
    block says which tool measured it, without a '(None)'."""
    import json

    (tmp_path / "reports").mkdir()
    comps = {"bc": "1", "sac": "2"}
    fingerprint = {"components": comps, "versions": {"torch": "x"}}
    (tmp_path / "reports" / "fingerprint.json").write_text(json.dumps(fingerprint))
    run = {"cpu": "AMD EPYC (avx512), native", "emulated_model": None, "numerics": "pinned", "components": comps,
           "matches_committed": {"bc": True, "sac": True}, "all_match": True}
    doc = {"date": "2026-12-07", "host_cpu_model": "AMD EPYC", "host_cpu_isa": "avx512", "qemu": None,
           "committed": comps, "runs": [run], "earlier_hosts": []}
    (tmp_path / "reports" / "cross_cpu.json").write_text(json.dumps(doc))
    text = docs.cross_cpu(tmp_path)
    assert "| AMD EPYC | AVX-512 | pinned | yes, all 2 components compared |" in text
    assert "with `python tools/cross_cpu.py`; components bc, sac" in text and "None" not in text
    doc["qemu"] = "qemu-x86_64 version 7.2.22"
    (tmp_path / "reports" / "cross_cpu.json").write_text(json.dumps(doc))
    assert "`python tools/cross_cpu.py` (qemu-x86_64 version 7.2.22); components" in docs.cross_cpu(tmp_path)


def test_a_search_without_a_finished_trial_is_left_out_not_an_error(tmp_path: Path):
    """tools/dev_search.py writes its table's header before the first trial ends; `make docs` meanwhile goes on."""
    exp = tmp_path / "docs" / "experiments"
    exp.mkdir(parents=True)
    (exp / "trials.csv").write_text("date,trial,method,demos,seeds,cpu_model,numerics\n"
                                    "2026-12-06,t,lfdt,50,40,Some CPU,pinned\n")
    (exp / "search_st-new.csv").write_text("trial,baseline,repeat_of,translator.lambda_dyn,success_pct\n")
    assert "st-new" not in docs.search(tmp_path)
