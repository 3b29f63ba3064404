"""DVC stage: reports/twin_runs.csv and reports/twin.md, our results beside the paper's real-robot numbers."""

import argparse
import json
from pathlib import Path

from lfdt import methods, stage
from lfdt.evaluation import wilson_interval
from lfdt.robot import twin, twin_pipeline


def run() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--params", default="params.yaml")
    args = ap.parse_args()
    p = stage.params(args.params).twin
    rows, lines = [], []
    source = "MuJoCo twin" if p.backend == "sim" else "the robots"
    lines += [f"# Real-robot tasks ({source})", "",
              "| task | method | ours | 95 % CI | paper (real robots) |", "| --- | --- | --- | --- | --- |"]
    for task in twin.TASKS:
        ev = json.loads(Path(f"reports/twin/{task}_eval.json").read_text())
        rows += [{k: r[k] for k in ("task", "method", "trial", "success")} for r in ev["per_trial"]]
        for method in twin_pipeline.METHODS:
            trials = [r for r in ev["per_trial"] if r["method"] == method]
            k, n = sum(r["success"] for r in trials), len(trials)
            lo, hi = wilson_interval(k, n)
            pk, pn = twin_pipeline.PAPER_REAL[task][method]
            ci = f"{100 * lo:.0f}–{100 * hi:.0f} %"
            lines.append(f"| {task} | {methods.get(method).title} | {k}/{n} | {ci} | {pk}/{pn} |")
    lines += ["", f"Data per task: {p.random_samples} random-motion samples per domain, {p.demos_per_pairing} + "
              f"{p.demos_per_pairing} demonstrations, {p.trials} trials per method, seed {p.seed}. "
              "Paper: Kobayashi et al. 2023, §IV-E."]
    stage.write_csv("reports/twin_runs.csv", rows)
    Path("reports/twin.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    stage.main(run)
