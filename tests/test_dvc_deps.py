"""Every stage's deps in dvc.yaml list every project module its command imports (directly or through other
project modules), so a code change can never leave a stale result behind."""

import ast
import itertools
import re
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "lfdt"


def module_file(name: str) -> Path | None:
    """The file of a project module ``lfdt.x.y`` (a module or a package's __init__), or None."""
    parts = name.split(".")
    if parts[0] != PACKAGE:
        return None
    base = ROOT.joinpath(*parts)
    for cand in (base.with_suffix(".py"), base / "__init__.py"):
        if cand.exists():
            return cand
    return None


def imports_of(path: Path) -> set[str]:
    """Project modules a file imports (``import lfdt.x``, ``from lfdt import x``, ``from lfdt.x import y``),
    at any place in the file (stages import lazily inside functions too), and those its jobs' workers import
    (``parallel.Job("lfdt.x", "fn")``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    pkg = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == PACKAGE}
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:  # relative import inside the package
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                mod = ".".join(base + ([mod] if mod else []))
            if mod.split(".")[0] != PACKAGE:
                continue
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names if module_file(f"{mod}.{a.name}")}
        elif (isinstance(node, ast.Call) and _called_name(node.func) == "Job" and node.args
              and isinstance(node.args[0], ast.Constant) and str(node.args[0].value).split(".")[0] == PACKAGE):
            out.add(node.args[0].value)  # lfdt.parallel.Job("lfdt.x", "fn"): its workers import lfdt.x
    # importing lfdt.a.b runs lfdt/__init__.py and lfdt/a/__init__.py first
    for m in list(out):
        parts = m.split(".")
        out |= {".".join(parts[:i]) for i in range(1, len(parts))}
    return out


def _called_name(func: ast.expr) -> str | None:
    """The name a call calls: ``Job`` for ``Job(...)`` and ``parallel.Job(...)``."""
    return func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else None


def closure(script: Path) -> set[Path]:
    """Files of every project module the script imports, transitively, plus the script itself."""
    seen: set[Path] = {script}
    todo = [script]
    while todo:
        for name in imports_of(todo.pop()):
            f = module_file(name)
            if f is not None and f not in seen:
                seen.add(f)
                todo.append(f)
    return seen


def inert(path: Path) -> bool:
    """A package's __init__.py that holds nothing but a docstring changes nothing a stage computes."""
    if path.name != "__init__.py":
        return False
    body = ast.parse(path.read_text()).body
    return all(isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant) for n in body)


def covered(path: Path, deps: list[str]) -> bool:
    rel = path.relative_to(ROOT).as_posix()
    return any(rel == d or rel.startswith(d.rstrip("/") + "/") for d in deps)


REGISTRY = ROOT / "lfdt" / "tasks" / "registry.py"
"""The task registry imports a task's module by name (importlib), out of the reach of :func:`imports_of`."""


RUN_BY_PATH = {ROOT / "lfdt" / "policy_models.py": ROOT / "lfdt" / "policy_pyfunc.py"}
"""Files a module hands to another program by path rather than importing them: MLflow runs a policy model's code
file (``lfdt.policy_models.MODEL_CODE``) when it logs and loads the model."""


def task_module(name: str) -> Path:
    """The file of the module that holds task ``name``'s object, as the registry names it."""
    from lfdt.tasks import registry

    return module_file(registry.TASKS[name].split(":")[0])


def served_tasks(item: dict) -> list[str]:
    """The tasks a stage instance looks up in the registry: its matrix item's ``task``, else every task."""
    from lfdt.tasks import registry

    return [item["task"]] if "task" in item else list(registry.NAMES)


def required(cmd: str, item: dict) -> set[Path]:
    """Every project file a stage instance's command runs: the import closure of its scripts and modules and, where
    that holds the registry, the closure of the module of each task it serves."""
    files: set[Path] = set()
    for s in re.findall(r"(stages/[\w/]+\.py)", cmd):
        files |= closure(ROOT / s)
    for m in re.findall(r"python -m ([\w.]+)", cmd):
        files |= closure(module_file(m))
    if REGISTRY in files:
        for task in served_tasks(item):
            files |= closure(task_module(task))
    for module, code in RUN_BY_PATH.items():
        if module in files:
            files |= closure(code)
    return files


def missing_deps(cmd: str, deps: list[str], item: dict) -> list[str]:
    return sorted(f.relative_to(ROOT).as_posix() for f in required(cmd, item) if not covered(f, deps) and not inert(f))


def package_code(folder: Path) -> set[str]:
    """Every file of a package folder (subpackages included) that can change what a stage computes, relative to the
    project's root."""
    return {f.relative_to(ROOT).as_posix() for f in folder.rglob("*.py") if "__pycache__" not in f.parts
            and not inert(f)}


def extra_deps(cmd: str, deps: list[str], item: dict) -> list[str]:
    """Code deps the stage does not run: a file it does not import, or a package folder one of whose files it does not
    import (a folder dep stands for all of its code)."""
    imported = {f.relative_to(ROOT).as_posix() for f in required(cmd, item)}
    return [d for d in deps if (d.endswith(".py") and d not in imported)
            or (d.startswith(PACKAGE + "/") and not d.endswith(".py") and not package_code(ROOT / d) <= imported)]


def _lookup(doc: dict, dotted: str):
    for key in dotted.split("."):
        doc = doc[key]
    return doc


def matrix_items(matrix: dict) -> list[dict]:
    """A matrix stage's items, as DVC expands them (``${a.b}`` values from params.yaml or dvc.yaml's vars)."""
    params = yaml.safe_load((ROOT / "params.yaml").read_text())
    for v in yaml.safe_load((ROOT / "dvc.yaml").read_text()).get("vars", []):
        if isinstance(v, dict):
            params = {**params, **v}
    axes = {}
    for key, values in matrix.items():
        ref = re.fullmatch(r"\$\{([\w.]+)\}", values) if isinstance(values, str) else None
        axes[key] = _lookup(params, ref.group(1)) if ref else values
    return [dict(zip(axes, combo)) for combo in itertools.product(*axes.values())]


def _expand(text: str, item: dict) -> str:
    return re.sub(r"\$\{item\.(\w+)\}", lambda m: str(item[m.group(1)]), text)


def stages() -> list[tuple[str, str, list[str], dict]]:
    """Every stage instance (a matrix stage once per item, named as DVC names it) with its command and deps."""
    doc = yaml.safe_load((ROOT / "dvc.yaml").read_text())
    out = []
    for name, st in doc["stages"].items():
        deps = [d if isinstance(d, str) else next(iter(d)) for d in st.get("deps", [])]
        cmd = " && ".join(st["cmd"]) if isinstance(st["cmd"], list) else st["cmd"]  # a stage of several commands
        for item in matrix_items(st["matrix"]) if "matrix" in st else [{}]:
            label = name + ("@" + "-".join(map(str, item.values())) if item else "")
            out.append((label, _expand(cmd, item), [_expand(d, item) for d in deps], item))
    return out


STAGES = stages()


@pytest.mark.parametrize("name, cmd, deps, item", STAGES, ids=[s[0] for s in STAGES])
def test_stage_deps_cover_import_closure(name, cmd, deps, item):
    assert re.findall(r"(stages/[\w/]+\.py)", cmd) or re.findall(r"python -m ([\w.]+)", cmd), \
        f"stage {name}: no stage script found in its cmd {cmd!r}"
    missing = missing_deps(cmd, deps, item)
    assert not missing, f"stage {name} imports {missing} but dvc.yaml does not list them in its deps"


@pytest.mark.parametrize("name, cmd, deps, item", STAGES, ids=[s[0] for s in STAGES])
def test_stage_deps_list_no_code_the_stage_does_not_import(name, cmd, deps, item):
    """A code dep the command never imports reruns the stage for nothing (and every no-op repro checks it)."""
    extra = extra_deps(cmd, deps, item)
    assert not extra, f"stage {name} lists {extra} in its deps but never imports them"


def test_closure_follows_imports_transitively():
    # stages/train_translator.py imports lfdt.box_push_jobs.translator, which imports lfdt.translation.training (which
    # imports lfdt.translation.losses), lfdt.dynamics and lfdt.tasks.box_push.env
    files = {f.relative_to(ROOT).as_posix() for f in closure(ROOT / "stages/train_translator.py")}
    assert {"lfdt/translation/training.py", "lfdt/translation/losses.py", "lfdt/dynamics.py",
            "lfdt/tasks/box_push/env.py", "lfdt/config.py"} <= files


def test_a_policy_models_code_file_is_a_dep_of_the_stage_that_logs_it():
    """MLflow runs lfdt/policy_pyfunc.py by path: an edit of it must rerun the stage that logs the models."""
    from lfdt.policy_models import MODEL_CODE

    assert RUN_BY_PATH[ROOT / "lfdt" / "policy_models.py"] == MODEL_CODE
    name, cmd, deps, item = next(s for s in STAGES if s[0] == "register_policies")
    assert "lfdt/policy_pyfunc.py" in deps
    assert missing_deps(cmd, [d for d in deps if d != "lfdt/policy_pyfunc.py"], item) == ["lfdt/policy_pyfunc.py"]


def test_a_stage_that_looks_its_task_up_depends_on_that_task_alone():
    """The registry imports by name: a twin stage instance needs its own task's module (and what it imports), and
    another task's module is no dep of it."""
    name, cmd, deps, item = next(s for s in STAGES if s[0] == "twin_collect@block_push")
    assert "lfdt/tasks/block_push.py" in deps and REGISTRY in required(cmd, item)
    assert missing_deps(cmd, [d for d in deps if d != "lfdt/tasks/block_push.py"], item) == \
        ["lfdt/tasks/block_push.py"]
    assert extra_deps(cmd, [*deps, "lfdt/tasks/peg_insertion.py"], item) == ["lfdt/tasks/peg_insertion.py"]


EVERY_TASK_STAGES = ("preflight", "register_policies")
"""Stages that serve Table I's task and the twin's alike (they look every task up in the registry; preflight checks
the twin's task names before any stage runs)."""


def test_table1_stages_depend_on_no_other_task():
    """The box push's stages import its modules directly, never the registry: no other task's code is theirs."""
    for name, cmd, _, item in STAGES:
        if name.startswith("twin_") or name in EVERY_TASK_STAGES:
            continue
        files = {f.relative_to(ROOT).as_posix() for f in required(cmd, item)}
        assert REGISTRY.relative_to(ROOT).as_posix() not in files, name
        assert not [f for f in files if f.startswith(("lfdt/twin/", "lfdt/robot/", "lfdt/tasks/block_push",
                                                      "lfdt/tasks/peg_insertion", "lfdt/tasks/base"))], name


def test_lock_holds_only_stages_dvc_yaml_defines():
    """DVC keeps the lock entries of removed stages (treeverse/dvc#5293); they slow every status and repro."""
    from lfdt.lockfile import defined_stages, stale_stages

    lock = yaml.safe_load((ROOT / "dvc.lock").read_text())
    stale = stale_stages(lock, defined_stages(ROOT))
    assert not stale, f"dvc.lock holds {len(stale)} stages dvc.yaml does not define, e.g. {stale[:3]}: " \
                      "run `python -m lfdt.lockfile --prune`"


def test_prune_removes_only_stale_entries(tmp_path):
    from lfdt.lockfile import prune

    lock = tmp_path / "dvc.lock"
    lock.write_text((ROOT / "dvc.lock").read_text().replace(
        "stages:\n", "stages:\n  gone@1:\n    cmd: python stages/gone.py\n", 1))
    defined = set(yaml.safe_load((ROOT / "dvc.lock").read_text())["stages"])
    assert prune(lock, defined) == ["gone@1"]
    assert lock.read_text() == (ROOT / "dvc.lock").read_text()
    assert prune(lock, defined) == []
