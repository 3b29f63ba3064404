"""Every number the README and docs/ take from reports/ or benchmarks/results/ is what those files say now."""

import lfdt.numerics  # noqa: F401

from pathlib import Path

import pytest

from lfdt import docs


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
    with pytest.raises(KeyError, match="unknown generated block 'nope'"):
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
