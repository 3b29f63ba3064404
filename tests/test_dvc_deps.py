"""Every stage's deps in dvc.yaml list every project module its command imports (directly or through other
project modules), so a code change can never leave a stale result behind."""

import ast
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
    at any place in the file (stages import lazily inside functions too)."""
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
    # importing lfdt.a.b runs lfdt/__init__.py and lfdt/a/__init__.py first
    for m in list(out):
        parts = m.split(".")
        out |= {".".join(parts[:i]) for i in range(1, len(parts))}
    return out


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


def stages() -> list[tuple[str, str, list[str]]]:
    doc = yaml.safe_load((ROOT / "dvc.yaml").read_text())
    return [(name, st["cmd"], [d if isinstance(d, str) else next(iter(d)) for d in st.get("deps", [])])
            for name, st in doc["stages"].items()]


@pytest.mark.parametrize("name, cmd, deps", stages(), ids=[s[0] for s in stages()])
def test_stage_deps_cover_import_closure(name, cmd, deps):
    scripts = re.findall(r"(stages/[\w/]+\.py)", cmd)
    modules = re.findall(r"python -m ([\w.]+)", cmd)
    assert scripts or modules, f"stage {name}: no stage script found in its cmd {cmd!r}"
    files: set[Path] = set()
    for s in scripts:
        files |= closure(ROOT / s)
    for m in modules:
        files |= closure(module_file(m))
    missing = sorted(f.relative_to(ROOT).as_posix() for f in files if not covered(f, deps) and not inert(f))
    assert not missing, f"stage {name} imports {missing} but dvc.yaml does not list them in its deps"


@pytest.mark.parametrize("name, cmd, deps", stages(), ids=[s[0] for s in stages()])
def test_stage_deps_list_no_code_the_stage_does_not_import(name, cmd, deps):
    """A code dep the command never imports reruns the stage for nothing (and every no-op repro checks it)."""
    files: set[Path] = set()
    for s in re.findall(r"(stages/[\w/]+\.py)", cmd):
        files |= closure(ROOT / s)
    for m in re.findall(r"python -m ([\w.]+)", cmd):
        files |= closure(module_file(m))
    imported = {f.relative_to(ROOT).as_posix() for f in files}
    extra = [d for d in deps if d.endswith(".py") and d not in imported]
    assert not extra, f"stage {name} lists {extra} in its deps but never imports them"


def test_closure_follows_imports_transitively():
    # stages/train_translator.py imports lfdt.jobs.translator, which imports lfdt.translation, lfdt.dynamics and
    # lfdt.envs
    files = {f.relative_to(ROOT).as_posix() for f in closure(ROOT / "stages/train_translator.py")}
    assert {"lfdt/translation.py", "lfdt/dynamics.py", "lfdt/envs.py", "lfdt/config.py"} <= files


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
