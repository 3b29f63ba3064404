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
