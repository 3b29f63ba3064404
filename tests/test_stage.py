"""The helpers every stage script shares."""

import csv
from pathlib import Path

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


def test_a_diverging_loss_stops_training_with_a_clear_error():
    import numpy as np
    import pandas as pd
    import pytest

    from lfdt import bc
    from lfdt.config import BCConfig
    from lfdt.nets import TrainingDiverged

    rng = np.random.default_rng(0)
    frame = pd.DataFrame({"state.a": rng.normal(size=64), "state.b": rng.normal(size=64),
                          "action.u": rng.normal(size=64), "episode_index": np.repeat(np.arange(8), 8)})
    frame.loc[5, "action.u"] = np.nan  # one bad label poisons the loss
    task = bc.BCTask("pi", ["a", "b"], ["u"], frame)
    with pytest.raises(TrainingDiverged, match=r"the BC loss is nan at iteration \d+: training diverged"):
        bc.train_member(task, BCConfig(hidden=[8], iterations=50, eval_every=10, batch_size=64), seed=0)


def test_a_report_is_split_into_measured_results_and_bookkeeping(tmp_path):
    import json

    metrics = tmp_path / "reports" / "bc" / "lfdt-d50.json"
    metrics.parent.mkdir(parents=True)
    report = {"method": "lfdt", "stage_wall_s": 12.5,
              "seeds": {"3": {"success_rate": 0.5, "mlflow_run_id": "abc", "job_wall_s": 3.0, "iterations_per_s": 9.0},
                        "4": {"success_rate": 0.25}}}
    stage.write_report(metrics, report)
    measured = json.loads(metrics.read_text())
    books = json.loads((tmp_path / "runs" / "bc" / "lfdt-d50.json").read_text())
    assert measured == {"method": "lfdt", "seeds": {"3": {"success_rate": 0.5}, "4": {"success_rate": 0.25}}}
    assert books == {"stage_wall_s": 12.5, "seeds": {"3": {"mlflow_run_id": "abc", "job_wall_s": 3.0,
                                                              "iterations_per_s": 9.0}}}
    assert stage.read_report(metrics) == report
    assert stage.run_ids(books) == ["abc"]
    assert stage.run_ids({"mlflow_run_id": "p", "seeds": {"3": {"mlflow_run_id": "s3"}, "4": {}}}) == ["p", "s3"]
    # the same results from a second run (other ids and times): the metrics file is byte-identical
    before = metrics.read_bytes()
    stage.write_report(metrics, {**report, "stage_wall_s": 99.0})
    assert metrics.read_bytes() == before


def test_a_report_outside_reports_or_without_its_bookkeeping_is_refused(tmp_path):
    import pytest

    from lfdt.errors import StageError

    with pytest.raises(StageError, match="must lie under reports/"):
        stage.write_report(tmp_path / "data" / "x.json", {"a": 1})
    metrics = tmp_path / "reports" / "x.json"
    metrics.parent.mkdir()
    metrics.write_text("{}")
    with pytest.raises(StageError, match=r"runs/x\.json is missing"):
        stage.read_report(metrics)


def test_the_bookkeeping_of_a_report_lies_under_the_last_reports_folder():
    from pathlib import Path

    assert stage.runs_path("reports/bc/lfdt-d50.json") == Path("runs/bc/lfdt-d50.json")
    assert stage.runs_path("/tmp/reports/x/reports/y.json") == Path("/tmp/reports/x/runs/y.json")
    assert stage.runs_path("reports/reports.json") == Path("runs/reports.json")


def test_the_stage_frame_writes_the_report_with_its_run_id_and_wall_time(tmp_path, monkeypatch):
    import json

    import mlflow

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    path = tmp_path / "reports" / "random" / "Y.json"
    path.parent.mkdir(parents=True)
    with stage.frame(path, "unit", {"a": 1}, tags={"domain": "Y"}, run_name="Y unit") as f:
        with f.progress(3, "unit") as bar:
            bar.update(3)
        f.metrics({"transitions": 3, "rate": 0.5, "ok": True, "domain": "Y"})
        f.report.update({"domain": "Y", "transitions": 3, "ok": True})
        run_id = f.run.run_id
    assert json.loads(path.read_text()) == {"domain": "Y", "transitions": 3, "ok": True}
    books = json.loads((tmp_path / "runs" / "random" / "Y.json").read_text())
    assert list(books) == ["stage_wall_s", "mlflow_run_id"]  # the order every stage wrote them in before
    assert books["mlflow_run_id"] == run_id and books["stage_wall_s"] > 0
    run = mlflow.MlflowClient(uri).get_run(run_id)
    assert run.info.status == "FINISHED" and run.info.run_name == "Y unit"
    assert run.data.tags["lfdt.stage"] == "unit" and run.data.params == {"a": "1"}
    # booleans are flags, not measurements; strings are no metrics
    assert set(run.data.metrics) == {"transitions", "rate", "stage_wall_s"}


def test_the_numeric_filter_keeps_numbers_but_no_booleans():
    import numpy as np

    got = stage.numeric({"a": 1, "b": 2.5, "c": True, "d": False, "e": "x", "f": None, "g": {"h": 1},
                         "i": np.float32(0.5), "j": np.int64(3), "k": np.True_})
    assert got == {"a": 1, "b": 2.5, "i": 0.5, "j": 3}


def test_a_stage_frame_without_a_run_adds_only_the_wall_time(tmp_path):
    import json

    import pytest

    from lfdt.errors import StageError

    path = tmp_path / "reports" / "bc" / "lfdt-d3.json"
    path.parent.mkdir(parents=True)
    with stage.frame(path) as f:  # a matrix stage: its jobs open their own runs
        f.report.update({"method": "lfdt", "demos": 3, "seeds": {"0": {"success_rate": 0.5, "mlflow_run_id": "a"}}})
        assert f.run is None
        with pytest.raises(StageError, match="opened no MLflow run"):
            f.metrics({"x": 1.0})
    assert json.loads(path.read_text()) == {"method": "lfdt", "demos": 3, "seeds": {"0": {"success_rate": 0.5}}}
    books = json.loads((tmp_path / "runs" / "bc" / "lfdt-d3.json").read_text())
    assert list(books) == ["seeds", "stage_wall_s"] and books["seeds"] == {"0": {"mlflow_run_id": "a"}}


def test_an_error_inside_the_stage_frame_writes_no_report_and_fails_the_run(tmp_path, monkeypatch):
    import mlflow
    import pytest

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    path = tmp_path / "reports" / "x.json"
    path.parent.mkdir(parents=True)
    with pytest.raises(RuntimeError, match="diverged"), stage.frame(path, "unit", {}) as f:
        f.report["a"] = 1
        run_id = f.run.run_id
        raise RuntimeError("diverged")
    assert not path.exists() and not (tmp_path / "runs").exists()
    assert mlflow.MlflowClient(uri).get_run(run_id).info.status == "FAILED"


def test_a_stage_refuses_a_missing_path_argument(monkeypatch, capsys):
    import pytest

    ap = stage.parser("unit", {"out-dir": "where it goes"})
    with pytest.raises(SystemExit) as err:
        ap.parse_args([])
    assert err.value.code == 2
    assert "the following arguments are required: --out-dir" in capsys.readouterr().err
    assert ap.parse_args(["--out-dir", "data/random"]).out_dir == Path("data/random")


def _noted(err: OSError, note: str) -> OSError:
    err.add_note(note)
    return err


def test_stage_main_ends_a_params_problem_a_full_disk_or_ctrl_c_in_one_line(tmp_path, monkeypatch, capsys):
    """Every stage runs in lfdt.stage.main: what comes from outside the code is one line on stderr and an exit code
    (2, or 130 for Ctrl-C), never a traceback; the OS's reason without its ``[Errno N]``, the file where it named one,
    and what the code added to the error (its notes)."""
    import pytest

    from lfdt.config import ParamsError

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("lfdt.lifeline.LOCK_DIR", tmp_path / "locks")
    cases = [
        (ParamsError("params.yaml: bc.iterations: required"), 2, "error: params.yaml: bc.iterations: required"),
        (OSError(28, "No space left on device", "out.json"), 2, "error: out.json: No space left on device"),
        (OSError(28, "No space left on device"), 2, "error: No space left on device"),
        (_noted(OSError(13, "Permission denied", "m.pt"), "the policy's weights"), 2,
         "error: m.pt: Permission denied; the policy's weights"),
        (KeyboardInterrupt(), 130,
         "error: interrupted (Ctrl-C): the stage's outputs are incomplete; `dvc repro` reruns it"),
    ]
    for exc, code, line in cases:
        def fail(exc: BaseException = exc) -> None:
            raise exc

        with pytest.raises(SystemExit) as stop:
            stage.main(fail)
        assert stop.value.code == code, (exc, stop.value.code)
        assert capsys.readouterr().err == line + "\n", exc
    stage.main(lambda: None)  # a stage that ends well returns
    assert capsys.readouterr().err == ""


def test_a_refused_command_line_is_one_line(capsys):
    """Every command line's parser (stages, the robot CLI, the sweep, restore, the views) refuses in one line, without
    argparse's usage lines before it."""
    import pytest

    from lfdt.robot.cli import build_parser

    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(["deploy", "--trials", "0", "--sim"])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.count("\n") == 1 and err.startswith("error: python -m lfdt.robot deploy: "), err
    assert "--trials: 0 is not a positive count" in err and "`python -m lfdt.robot deploy --help`" in err
    with pytest.raises(SystemExit):
        stage.parser("a stage", {"out": "where"}).parse_args([])
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the following arguments are required: --out" in err, err
