"""The package's layers (docs/architecture.md): no import cycle, and no import from a lower layer to a higher one.

Imports are read from the source (``ast``), lazy ones inside functions included; those under ``if TYPE_CHECKING:``
are left out: they exist for type hints only and never run.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "lfdt"

HIGHER = ("lfdt.tasks", "lfdt.twin", "lfdt.robot", "lfdt.rig", "lfdt.box_push_jobs", "lfdt.sweep")
LAYERS: dict[str, tuple[str, ...]] = {
    "lfdt.tasks": ("lfdt.rig", "lfdt.twin", "lfdt.robot", "lfdt.box_push_jobs", "lfdt.sweep"),
    "lfdt.rig": ("lfdt.twin", "lfdt.robot", "lfdt.box_push_jobs", "lfdt.sweep"),
    "lfdt.twin": ("lfdt.robot", "lfdt.box_push_jobs", "lfdt.sweep"),
    "lfdt.box_push_jobs": ("lfdt.rig", "lfdt.twin", "lfdt.robot", "lfdt.sweep"),
    **{m: HIGHER for m in ("lfdt.translation", "lfdt.bc", "lfdt.dynamics", "lfdt.evaluation", "lfdt.nets",
                           "lfdt.optim", "lfdt.poses", "lfdt.config", "lfdt.data", "lfdt.layout", "lfdt.stage",
                           "lfdt.mlflow_runs", "lfdt.parallel", "lfdt.seeding", "lfdt.files", "lfdt.errors")},
}
"""A module (or package) and what it must never import: the tasks and the hardware-free rig sit below the twin's
pipeline, which sits below the robots' command line; Table I's jobs sit beside the twin's; the learning code and the
shared modules serve every task through its layout and import none."""

BOX_PUSH_HOMES = ("lfdt.tasks.box_push", "lfdt.box_push_jobs")
"""The only packages that import the box push directly: its own, and Table I's jobs (which say in their name that
they are its). Everything else reaches a task by name through :mod:`lfdt.tasks.registry`."""


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _type_checking_lines(tree: ast.AST) -> set[int]:
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", getattr(node.test, "attr", None)) == "TYPE_CHECKING":
            for child in node.body:
                lines |= set(range(child.lineno, (child.end_lineno or child.lineno) + 1))
    return lines


def runtime_imports(path: Path, name: str | None = None) -> set[str]:
    """The lfdt modules a file (module ``name``, by default from its path) imports when it runs, at module level or
    inside functions."""
    tree = ast.parse(path.read_text())
    hints = _type_checking_lines(tree)
    here = (name or module_name(path)).split(".")
    is_pkg = path.name == "__init__.py"
    out = set()
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in hints:
            continue
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("lfdt")}
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                base = here if is_pkg else here[:-1]
                base = base[: len(base) - node.level + 1]
                mod = ".".join(base + ([mod] if mod else []))
            if not mod.startswith("lfdt"):
                continue
            for a in node.names:
                sub = f"{mod}.{a.name}"
                out.add(sub if _exists(sub) else mod)
    return {m for m in out if m != "lfdt" and m != "lfdt.numerics"}


def _exists(name: str) -> bool:
    base = ROOT.joinpath(*name.split("."))
    return base.with_suffix(".py").exists() or (base / "__init__.py").exists()


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py")) if "__pycache__" not in p.parts}
GRAPH = {name: runtime_imports(path) & set(MODULES) for name, path in MODULES.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (module -> the modules it imports), as a path back to its start, or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 1:
                return stack[stack.index(n):] + [n]
            if n not in state and (found := visit(n)):
                return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (found := visit(m)):
            return found
    return None


def test_no_import_cycle():
    cycle = find_cycle(GRAPH)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


@pytest.mark.parametrize("layer", sorted(LAYERS))
def test_no_import_into_a_higher_layer(layer):
    bad = [f"{m} imports {n}" for m, deps in GRAPH.items() if m == layer or m.startswith(layer + ".")
           for n in deps for above in LAYERS[layer] if n == above or n.startswith(above + ".")]
    assert not bad, "\n".join(bad)


def test_only_the_box_push_and_its_jobs_import_it_directly():
    importers = {m for m, deps in GRAPH.items() if not m.startswith(BOX_PUSH_HOMES)
                 and any(n.startswith("lfdt.tasks.box_push") for n in deps)}
    assert not importers, f"import the box push through lfdt.tasks.registry instead: {sorted(importers)}"


def test_the_checks_can_fail(tmp_path):
    """The reader sees a lazy import, and skips one made for type hints only."""
    f = tmp_path / "m.py"
    f.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from lfdt.twin import common\n"
                 "def g():\n    from lfdt.robot import cli\n")
    assert runtime_imports(f, "lfdt.m") == {"lfdt.robot.cli"}
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None
