"""The method registry: a method is one record, and a new one (an ablation) needs nothing else changed."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from lfdt import methods, report
from lfdt.config import ParamsError, validate_params

TOY = methods.Method("lfdt_no_adv", "LfDT w/o adversarial loss", "translated", translator="lfdt_no_adv",
                     overrides={"lambda_adv": 0.0}, colour="tab:green", ours=True)
"""A toy ablation: LfDT without L_adv."""


@pytest.fixture
def toy(monkeypatch):
    monkeypatch.setitem(methods.METHODS, TOY.name, TOY)
    return TOY


def _trials(method_names: list[str]) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    rows = [{"method": m, "demos": d, "seed": s, "trial": t, "start_states": "evaluation",
             "success": bool(rng.random() < 0.5), "path_success": bool(rng.random() < 0.3),
             "final_box_distance_m": 0.01, "final_yaw_error_rad": 0.01}
            for m in method_names for d in (50, 100) for s in (3, 4) for t in range(20)]
    return pd.DataFrame(rows)


def test_a_toy_method_is_one_registry_entry(toy):
    # params: the grid accepts it as a translator and as a row of Table I
    p = validate_params({"grid": {"translator_methods": ["lfdt", "lfdt_no_adv"],
                                  "bc_methods": ["bc_no_translation", "lfdt", "lfdt_no_adv"]}})
    assert "lfdt_no_adv" in methods.translator_methods()
    # the translator stage's config: its override, nothing else
    cfg = methods.translator_config("lfdt_no_adv", p.translator)
    assert cfg.lambda_adv == 0.0 and cfg.model_copy(update={"lambda_adv": p.translator.lambda_adv}) == p.translator
    # the report: its row, in the registry's order, with its title and no paper value
    table = report.aggregate(_trials(["lfdt_no_adv", "bc_no_translation", "lfdt"]))
    assert list(dict.fromkeys(table.method)) == ["bc_no_translation", "lfdt", "lfdt_no_adv"]
    assert table[table.method == "lfdt_no_adv"].paper_success_rate.isna().all()
    md = report.markdown(table)
    assert "| LfDT w/o adversarial loss |" in md and md.index("| LfDT |") < md.index("| LfDT w/o adversarial")
    assert "lfdt_no_adv" in report.success_by_method(table).columns


def test_without_its_entry_the_toy_method_is_refused():
    with pytest.raises(ParamsError, match="lfdt_no_adv"):
        validate_params({"grid": {"translator_methods": ["lfdt", "lfdt_no_adv"]}})
    with pytest.raises(ValueError, match="unknown method 'lfdt_no_adv'"):
        methods.get("lfdt_no_adv")
