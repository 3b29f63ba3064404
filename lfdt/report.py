"""Table I: aggregation of the evaluation files into tables (md, csv, tex), a plot, and stage wall times."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from lfdt.evaluation import METHOD_TITLES, PAPER_TABLE1, seed_mean_interval, wilson_interval

METHOD_ORDER = ["bc_no_translation", "lfdt_no_dyn", "lfdt_no_id", "lfdt"]


def load_runs(eval_dir: Path) -> pd.DataFrame:
    """One row per (method, demos, seed) from reports/eval/*.json."""
    rows = []
    for f in sorted(Path(eval_dir).glob("*.json")):
        d = json.loads(f.read_text())
        rows.append({k: d[k] for k in ("method", "demos", "seed", "successes", "trials", "success_rate",
                                       "mean_final_box_distance_m", "mean_final_yaw_error_rad")})
    if not rows:
        raise FileNotFoundError(f"no evaluation results in {eval_dir}")
    df = pd.DataFrame(rows)
    df["order"] = df.method.map({m: i for i, m in enumerate(METHOD_ORDER)})
    return df.sort_values(["order", "demos", "seed"]).drop(columns="order").reset_index(drop=True)


def aggregate(runs: pd.DataFrame) -> pd.DataFrame:
    """Per (method, demos): mean over seeds, per-seed values, 95 % intervals, and the paper's value."""
    out = []
    for (method, demos), g in runs.groupby(["method", "demos"], sort=False):
        rates = g.success_rate.tolist()
        lo, hi = wilson_interval(int(g.successes.sum()), int(g.trials.sum()))
        slo, shi = seed_mean_interval(rates)
        out.append({"method": method, "demos": int(demos), "seeds": len(g), "trials": int(g.trials.sum()),
                    "successes": int(g.successes.sum()), "success_rate": float(np.mean(rates)),
                    "per_seed": ";".join(f"{r:.2f}" for r in rates),
                    "ci95_low": lo, "ci95_high": hi, "seed_ci95_low": slo, "seed_ci95_high": shi,
                    "paper_success_rate": PAPER_TABLE1.get(method, {}).get(int(demos), float("nan")) / 100})
    return pd.DataFrame(out)


def _pct(x: float) -> str:
    return "–" if x != x else f"{100 * x:.1f} %"


def markdown(table: pd.DataFrame) -> str:
    """Table I as markdown: ours (mean, per seed, 95 % interval) beside the paper's."""
    demos = sorted(table.demos.unique())
    head = "| method | " + " | ".join(f"{d} demos: ours | {d} demos: paper" for d in demos) + " |"
    sep = "| --- |" + " --- | --- |" * len(demos)
    lines = [head, sep]
    for method in [m for m in METHOD_ORDER if m in set(table.method)]:
        cells = []
        for d in demos:
            r = table[(table.method == method) & (table.demos == d)]
            if r.empty:
                cells += ["–", _pct(PAPER_TABLE1.get(method, {}).get(d, float("nan")) / 100)]
                continue
            r = r.iloc[0]
            cells.append(f"**{_pct(r.success_rate)}** ({r.per_seed.replace(';', ', ')}; "
                         f"95 % CI {100 * r.ci95_low:.0f}–{100 * r.ci95_high:.0f})")
            cells.append(_pct(r.paper_success_rate))
        lines.append(f"| {METHOD_TITLES[method]} | " + " | ".join(cells) + " |")
    n_seeds = int(table.seeds.max())
    trials = int(table.trials.max() // max(n_seeds, 1))
    lines.append("")
    lines.append(f"Success rate over {trials} trials per seed, mean over {n_seeds} seed(s); per-seed rates in "
                 "brackets; 95 % CI: Wilson interval of the pooled trials. Paper: Kobayashi et al. 2023, Table I.")
    return "\n".join(lines) + "\n"


def latex(table: pd.DataFrame) -> str:
    """Table I as a LaTeX tabular (ours / paper per demo count)."""
    demos = sorted(table.demos.unique())
    cols = "l" + "rr" * len(demos)
    lines = [r"\begin{tabular}{" + cols + "}", r"\toprule",
             "Method & " + " & ".join(rf"\multicolumn{{2}}{{c}}{{{d} demos}}" for d in demos) + r" \\",
             " & " + " & ".join("ours & paper" for _ in demos) + r" \\", r"\midrule"]
    for method in [m for m in METHOD_ORDER if m in set(table.method)]:
        cells = []
        for d in demos:
            r = table[(table.method == method) & (table.demos == d)]
            ours = "--" if r.empty else f"{100 * r.iloc[0].success_rate:.1f}"
            paper = PAPER_TABLE1.get(method, {}).get(d)
            cells += [ours, "--" if paper is None else f"{paper:.1f}"]
        lines.append(f"{METHOD_TITLES[method]} & " + " & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}"]
    return "\n".join(lines).replace("%", r"\%") + "\n"


def plot(runs: pd.DataFrame, table: pd.DataFrame, path: Path) -> Path:
    """Success rate against demo count: one line per method (mean over seeds), seeds as points, paper dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.4, 4.2), dpi=120)
    colours = {"bc_no_translation": "tab:gray", "lfdt_no_dyn": "tab:orange", "lfdt_no_id": "tab:red",
               "lfdt": "tab:blue"}
    for method in [m for m in METHOD_ORDER if m in set(table.method)]:
        t = table[table.method == method].sort_values("demos")
        c = colours[method]
        ax.plot(t.demos, 100 * t.success_rate, "-o", color=c, label=f"{METHOD_TITLES[method]} (ours)")
        r = runs[runs.method == method]
        jitter = (r.seed - r.seed.mean()) * 2.0
        ax.scatter(r.demos + jitter, 100 * r.success_rate, color=c, alpha=0.4, s=18)
        paper = PAPER_TABLE1.get(method, {})
        ax.plot(sorted(paper), [paper[d] for d in sorted(paper)], "--", color=c, alpha=0.5, lw=1)
    ax.set_xlabel("demonstrations per pairing")
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(-3, 103)
    ax.set_xticks(sorted(table.demos.unique()))
    ax.set_title("2D dual-arm box push (dashed: paper's Table I; points: seeds)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def stage_times(reports: Path) -> pd.DataFrame:
    """Wall time of every stage run that produced the current reports, summed per stage."""
    rows = []
    sources = {"train_experts": "experts/*_train.json", "collect_random": "random/*.json",
               "collect_demos": "demos/*.json", "fit_dynamics": "dynamics.json",
               "train_translator": "translator/*.json", "train_bc": "bc/*.json", "evaluate": "eval/*.json"}
    for name, pattern in sources.items():
        files = [f for f in sorted(reports.glob(pattern)) if not f.name.endswith("_curve.json")]
        walls = []
        for f in files:
            d = json.loads(f.read_text())
            w = d.get("stage_wall_s", d.get("wall_time_s", d.get("wall_s")))
            if w is not None:
                walls.append(float(w))
        if walls:
            rows.append({"stage": name, "runs": len(walls), "total_s": sum(walls), "mean_s": float(np.mean(walls))})
    return pd.DataFrame(rows)
