"""Candidate data for development trials: the pipeline's data stages with params changed as ``dvc exp run -S`` would,
outside the DVC pipeline, into ``dev/data/<name>/`` (git-ignored).

For trying a demonstration protocol or a kind of random motion before it goes into ``params.yaml``: it runs the
stage scripts themselves (``stages/*.py`` with ``--params``) on a copy of ``params.yaml`` with the changes, and
reuses the workspace's outputs for every stage it is not asked to run. ``tools/dev_trial.py --demos-dir/--random-dir/
--dynamics-dir`` then trains and evaluates on them.

    python tools/dev_data.py --name push50 --stages random dynamics -S random.push_fraction=0.5
    python tools/dev_trial.py --name push50 --random-dir dev/data/push50/random \\
        --dynamics-dir dev/data/push50/dynamics --demos 100 --methods lfdt
    python tools/dev_data.py --name wide-programs --stages experts demos -S demos.program.r1.speed=0.05
"""

import argparse
import os
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("experts", "random", "demos", "dynamics")
"""The data stages this tool runs, in pipeline order."""


def set_key(doc: dict, dotted: str, value: str) -> None:
    """Set ``dotted`` (an existing key of params.yaml) to ``value`` read as YAML; a missing key is an error."""
    keys = dotted.split(".")
    for k in keys[:-1]:
        if not isinstance(doc, dict) or k not in doc:
            raise SystemExit(f"-S {dotted}: no key {k!r} in params.yaml")
        doc = doc[k]
    if keys[-1] not in doc:
        raise SystemExit(f"-S {dotted}: no key {keys[-1]!r} in params.yaml")
    doc[keys[-1]] = yaml.safe_load(value)


def commands(stages: list[str], out: Path, params: Path) -> list[list[str]]:
    """The stage scripts to run, each reading the candidate's own outputs where it made them and the workspace's
    otherwise."""
    py = [sys.executable]
    experts = out / "experts" if "experts" in stages else ROOT / "models/experts"
    random = out / "random" if "random" in stages else ROOT / "data/random"
    reports = out / "reports"
    cmds = []
    if "experts" in stages:
        cmds.append(py + ["stages/train_experts.py", "--params", str(params), "--experts", str(experts),
                          "--checkpoints", str(out / "checkpoints"), "--reports", str(reports / "experts")])
    if "random" in stages:
        cmds += [py + ["stages/collect_random.py", "--params", str(params), "--domain", d, "--out-dir", str(random),
                       "--reports", str(reports / "random")] for d in ("Y", "R1H", "HR2")]
    if "demos" in stages:
        cmds += [py + ["stages/collect_demos.py", "--params", str(params), "--pairing", p, "--experts", str(experts),
                       "--out-dir", str(out / "demos"), "--reports", str(reports / "demos")] for p in ("R1H", "HR2")]
        cmds.append(py + ["stages/summarize_experts.py", "--params", str(params), "--expert-reports",
                          str((reports if "experts" in stages else ROOT / "reports") / "experts"),
                          "--demo-reports", str(reports / "demos"), "--out", str(reports / "experts.json")])
    if "dynamics" in stages:
        cmds.append(py + ["stages/fit_dynamics.py", "--params", str(params), "--random-dir", str(random),
                          "--out-dir", str(out / "dynamics"), "--report", str(reports / "dynamics.json"),
                          "--curve", str(reports / "dynamics_curve.csv")])
    return cmds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--name", required=True)
    ap.add_argument("--stages", nargs="+", choices=STAGES, required=True)
    ap.add_argument("-S", "--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    out = ROOT / "dev" / "data" / args.name
    out.mkdir(parents=True, exist_ok=True)
    doc = yaml.safe_load((ROOT / "params.yaml").read_text())
    for kv in args.set:
        key, _, value = kv.partition("=")
        set_key(doc, key, value)
    params = out / "params.yaml"
    params.write_text(yaml.safe_dump(doc, sort_keys=False))
    (out / "changes.txt").write_text(" ".join(args.set) + "\n")
    env = {**os.environ, "DVC_EXP_NAME": f"dev-data-{args.name}"}
    for cmd in commands([s for s in STAGES if s in args.stages], out, params):
        print("+", " ".join(os.path.relpath(c, ROOT) if c.startswith(str(ROOT)) else c for c in cmd), flush=True)
        rc = subprocess.run(cmd, cwd=ROOT, env=env).returncode
        if rc:
            raise SystemExit(f"tools/dev_data.py: {cmd[1]} failed with exit code {rc}")


if __name__ == "__main__":
    main()
