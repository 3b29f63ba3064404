"""params.yaml is validated before any compute; errors name the key and the value."""

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from lfdt.config import Params, ParamsError, load_params, render_defaults, validate_params

ROOT = Path(__file__).resolve().parents[1]


def test_repository_params_are_valid_and_complete():
    p = load_params(ROOT / "params.yaml")
    raw = yaml.safe_load((ROOT / "params.yaml").read_text())
    # every schema key is spelled out in params.yaml, so `dvc exp run -S` finds it
    assert set(raw) == set(Params.model_fields)
    assert p.random.transitions == 400_000 and p.demos.per_pairing == 200


def test_rendered_defaults_validate():
    validate_params(yaml.safe_load(render_defaults()))


def test_params_yaml_is_what_the_schema_renders():
    """Values and comments of params.yaml come from lfdt/config.py alone, so neither can drift from the other."""
    rendered = render_defaults() + "\n"
    text = (ROOT / "params.yaml").read_text()
    diff = [f"line {i + 1}: params.yaml {a!r} vs schema {b!r}"
            for i, (a, b) in enumerate(zip(text.splitlines(), rendered.splitlines())) if a != b]
    assert text == rendered, (
        "params.yaml differs from what lfdt/config.py renders (regenerate it with `python -c \"from lfdt.config "
        f"import render_defaults; print(render_defaults())\" > params.yaml`): {diff[:3] or 'line count differs'}")


@pytest.mark.parametrize("raw, key, value", [
    ({"experts": {"total_timesteps": -5}}, "experts.total_timesteps", "-5"),
    ({"random": {"transitions": 0}}, "random.transitions", "0"),
    ({"experts": {"learing_rate": 1e-3}}, "experts.learing_rate", "0.001"),
    ({"surprise": 1}, "surprise", "1"),
    ({"env": {"success": {"yaw": "small"}}}, "env.success.yaw", "'small'"),
    ({"env": {"success": {"distance": -0.1}}}, "env.success.distance", "-0.1"),
    ({"experts": {"gamma": 1.2}}, "experts.gamma", "1.2"),
    ({"demos": {"per_pairing": 2.5}}, "demos.per_pairing", "2.5"),
    ({"demos": {"deterministic": "yes"}}, "demos.deterministic", "'yes'"),
    ({"random": {"amplitude": 1.5}}, "random.amplitude", "1.5"),
    ({"experts": {"seed": 12}}, "experts.seed", "12"),
    ({"env": {"timestep": float("inf")}}, "env.timestep", "inf"),
    ({"translator": {"lambda_dyn": float("nan")}}, "translator.lambda_dyn", "nan"),
    ({"env": {"box": {"mass": float("-inf")}}}, "env.box.mass", "-inf"),
    ({"demos": {"per_pairing": 1e29}}, "demos.per_pairing", "accepted: an integer > 0 and <= 2147483647"),
    ({"demos": {"per_pairing": 10**29}}, "demos.per_pairing", "accepted: an integer > 0 and <= 2147483647"),
    ({"demos": {"per_pairing": 3_000}}, "demos", "more than max_attempts (2000)"),
])
def test_bad_values_name_key_and_value(raw, key, value):
    with pytest.raises(ParamsError) as err:
        validate_params(raw)
    msg = str(err.value)
    assert key in msg and value in msg


def test_cross_field_checks():
    with pytest.raises(ParamsError, match="hold_min"):
        validate_params({"random": {"hold_min": 4, "hold_max": 2}})
    with pytest.raises(ParamsError, match="gears has 2 entries but links has 3"):
        validate_params({"env": {"robot": {"links": [0.1, 0.1, 0.1], "gears": [1, 1], "damping": [1, 1, 1],
                                           "joint_range": [1, 1, 1]}}})


def test_impossible_shapes_and_section_errors_are_short():
    four = {"links": [0.1] * 4, "gears": [1.0] * 4, "damping": [1.0] * 4, "joint_range": [1.0] * 4}
    with pytest.raises(ParamsError, match=r"robot.links has 4 links; the state layout .* is built for 3"):
        validate_params({"env": {"robot": four}})
    with pytest.raises(ParamsError) as err:
        validate_params({"env": {"robot": {"links": [0.1, 0.1, 0.1], "gears": [1, 1], "damping": [1, 1, 1],
                                           "joint_range": [1, 1, 1]}}})
    # the section's error names the section and the reason, not the section's whole contents
    assert str(err.value) == "invalid params: env.robot: gears has 2 entries but links has 3"


def test_grid_cannot_ask_for_more_demos_than_collected():
    with pytest.raises(ParamsError, match="grid.demos asks for 200 .* demos.per_pairing collects only 100"):
        validate_params({"demos": {"per_pairing": 100}})


def test_not_a_mapping_and_missing_file(tmp_path):
    with pytest.raises(ParamsError, match="mapping"):
        validate_params([1, 2])
    with pytest.raises(ParamsError, match="nope.yaml: no such file"):
        load_params(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("env: [unclosed\n")
    with pytest.raises(ParamsError, match="not valid YAML"):
        load_params(bad)


def test_stage_stops_before_compute_with_named_key(tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text("random:\n  transitions: -3\n")
    proc = subprocess.run([sys.executable, str(ROOT / "stages/collect_random.py"), "--domain", "Y",
                           "--params", str(params), "--out-dir", "data/random", "--reports", "reports/random"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "random.transitions = -3" in proc.stderr
    assert not (tmp_path / "data").exists() and not (tmp_path / "mlflow.db").exists()


def test_a_twin_task_can_change_its_translator_settings():
    p = validate_params({"twin": {"task_translator": {"block_push": {"hand_offset": True, "iterations": 50}}}}).twin
    assert p.translator_for("block_push").hand_offset and p.translator_for("block_push").iterations == 50
    assert not p.translator_for("peg_insertion").hand_offset and p.translator_for("peg_insertion") == p.translator
    with pytest.raises(ParamsError, match="hand_ofset"):
        validate_params({"twin": {"task_translator": {"block_push": {"hand_ofset": True}}}})
    with pytest.raises(ParamsError, match=r"task_translator.block_push: kinematics = 'forward'"):
        validate_params({"twin": {"task_translator": {"block_push": {"kinematics": "forward"}}}})


def test_a_twin_task_can_change_its_bc_settings():
    p = validate_params({"twin": {"bc": {"iterations": 30}, "task_bc": {"block_push": {"input_noise": 0.2}}}}).twin
    assert p.bc_for("block_push").input_noise == 0.2 and p.bc_for("block_push").iterations == 30
    assert p.bc_for("peg_insertion") == p.bc
    with pytest.raises(ParamsError, match="input_nois"):
        validate_params({"twin": {"task_bc": {"block_push": {"input_nois": 0.1}}}})
    with pytest.raises(ParamsError, match="input_noise"):
        validate_params({"twin": {"task_bc": {"block_push": {"input_noise": -1.0}}}})


def test_twin_start_states_name_a_seed_block():
    assert validate_params({"twin": {"start_states": "development"}}).twin.start_states == "development"
    with pytest.raises(ParamsError, match="start_states"):
        validate_params({"twin": {"start_states": "training"}})


@pytest.mark.parametrize("path, says", [
    (["bc", "iterations"], "lacks bc.iterations (default 8000)"),
    (["twin", "bc", "iterations"], "lacks twin.bc.iterations (default 4000)"),
    (["bc"], "lacks section bc"),
])
def test_a_missing_key_is_an_error_not_the_code_default(tmp_path, path, says):
    """A key deleted from params.yaml would otherwise rerun its stages on lfdt/config.py's default, without a word."""
    raw = yaml.safe_load((ROOT / "params.yaml").read_text())
    section = raw
    for key in path[:-1]:
        section = section[key]
    del section[path[-1]]
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(raw, sort_keys=False))
    with pytest.raises(ParamsError) as err:
        load_params(params)
    assert f"{params} {says}" in str(err.value) and "\n" not in str(err.value)
