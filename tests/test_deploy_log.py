"""The deploy log: what `python -m lfdt.robot deploy` appends is what the twin_evaluate stage reads, and a log
that is not one fails with its file and line."""

import pytest

from lfdt.rig.deploy_log import DeployLogError, append_trial, read_trials


def test_appended_trials_read_back(tmp_path):
    log = tmp_path / "block_push" / "deploy_lfdt.csv"
    assert read_trials(log) == []
    for trial, ok in enumerate([True, False, True]):
        append_trial(log, trial, ok)
    assert read_trials(log) == [(0, True), (1, False), (2, True)]
    assert log.read_text().splitlines() == ["trial,success", "0,True", "1,False", "2,True"]


@pytest.mark.parametrize("text, where", [
    ("trial,outcome\n0,True\n", "header"),
    ("trial,success\n0,yes\n", "line 2"),
    ("trial,success\n0,true\n", "line 2"),
    ("trial,success\n0,True\n0,False\n", "line 3"),  # a repeated trial
    ("trial,success\n0,True\n2,False\n", "line 3"),  # a missing one
    ("trial,success\nx,True\n", "line 2"),
])
def test_a_bad_log_names_file_and_line(tmp_path, text, where):
    log = tmp_path / "deploy_lfdt.csv"
    log.write_text(text)
    with pytest.raises(DeployLogError, match=where) as err:
        read_trials(log)
    assert str(log) in str(err.value)
