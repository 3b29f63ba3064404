"""Rewrite every stage's code deps in dvc.yaml to the import closure of its command (what tests/test_dvc_deps.py
checks): after a change of imports, `python tools/sync_deps.py`, then look at the diff."""

import lfdt.numerics  # noqa: F401

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import test_dvc_deps as t  # noqa: E402


def _raw_deps(name: str) -> list[str]:
    import yaml

    st = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"][name]
    return [d if isinstance(d, str) else next(iter(d)) for d in st.get("deps", [])]


def collapse(mods: set[str]) -> list[str]:
    """The modules, with every package all of whose code the stage imports listed as its folder (one dep line
    instead of one per file; DVC hashes the folder, .dvcignore keeps __pycache__ out)."""
    out = set(mods)
    folders = {p.parent for p in (ROOT / "lfdt").rglob("*.py") if "__pycache__" not in p.parts} - {ROOT / "lfdt"}
    for folder in sorted(folders, key=lambda d: (len(d.parts), d)):  # outermost first
        files = t.package_code(folder)
        rel = folder.relative_to(ROOT).as_posix()
        if files and files <= out and not any(rel.startswith(d + "/") for d in out if not d.endswith(".py")):
            out = (out - files) | {rel}
    return sorted(out)


def main() -> None:
    text = (ROOT / "dvc.yaml").read_text()
    out, changed = [], []
    blocks = re.split(r"(?m)^(?=  [a-z_]+:\n)", text)
    for block in blocks:
        m = re.match(r"  ([a-z_]+):\n", block)
        name = m.group(1) if m else None
        stage = next((s for s in t.STAGES if name and s[0].split("@")[0] == name), None)
        if stage is None or "\n    deps:\n" not in block:
            out.append(block)
            continue
        items = [s for s in t.STAGES if s[0].split("@")[0] == name]
        need: set[str] = set()
        for _, cmd, deps_item, item in items:
            templated = [d for d, raw in zip(deps_item, _raw_deps(name)) if "${item." in raw]
            need |= {f.relative_to(ROOT).as_posix() for f in t.required(cmd, item)
                     if not t.inert(f) and not t.covered(f, templated)}
        head, rest = block.split("\n    deps:\n", 1)
        lines = rest.split("\n")
        deps = []
        while lines and lines[0].startswith("    - ") or (lines and lines[0].startswith("    #")):
            deps.append(lines.pop(0))
        code = [d for d in deps if re.match(r"    - (stages/[\w/]+\.py|lfdt/[\w/]+(\.py)?)$", d)]
        other = [d for d in deps if d not in code]
        scripts = sorted(n for n in need if n.startswith("stages/"))
        mods = collapse({n for n in need if n.startswith("lfdt/")})
        new_code = [f"    - {n}" for n in scripts + mods]
        if new_code != code:
            changed.append(name)
        out.append(head + "\n    deps:\n" + "\n".join(new_code + other + lines))
    (ROOT / "dvc.yaml").write_text("".join(out))
    print("deps rewritten:", ", ".join(changed) or "none")


if __name__ == "__main__":
    main()
