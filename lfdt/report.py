"""Table I: aggregation of the evaluation files into tables (md, csv, tex), a plot, translator diagnostics and
stage wall times. Methods, their titles, colours and the paper's values come from :mod:`lfdt.methods`."""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from lfdt import methods
from lfdt.evaluation import PAPER_TRIALS, paired_difference_interval, seed_state_interval


def method_order() -> list[str]:
    """Table I's row order: the registry's (read when asked, so that a method added to it is a row too)."""
    return list(methods.METHODS)


def _ordered(df: pd.DataFrame) -> pd.DataFrame:
    df = df.copy()
    df["order"] = df.method.map({m: i for i, m in enumerate(method_order())})
    return df.sort_values(["order", "demos", "seed"] if "seed" in df else ["order", "demos"]).drop(columns="order")


def load_trials(eval_dir: Path) -> pd.DataFrame:
    """Every evaluation trial: one row per (method, demos, seed, start state) from reports/eval/*_trials.csv."""
    files = sorted(Path(eval_dir).glob("*_trials.csv"))
    if not files:
        raise FileNotFoundError(f"no evaluation trials (*_trials.csv) in {eval_dir}; run `dvc repro`")
    df = pd.concat([pd.read_csv(f) for f in files], ignore_index=True)
    for col in CRITERIA:
        if col not in df:
            raise ValueError(f"{eval_dir}/*_trials.csv: no column {col!r} (trials written before the path rule; "
                             "run `dvc repro`)")
        df[col] = df[col].astype(str).str.lower().map({"true": True, "false": False, "1": True, "0": False})
        if df[col].isna().any():
            raise ValueError(f"unreadable {col} values in {eval_dir}/*_trials.csv")
    return _ordered(df).reset_index(drop=True)


CRITERIA = {"success": "", "path_success": "path_"}
"""The trial outcomes Table I reports, with the prefix of their columns: the end-state rule (the box at the goal,
straight and at rest) and, beside it, the path rule (that, and the box never turned further than its start or the
end-state threshold allow plus a margin: ``env.success.path_yaw_margin``)."""


def runs(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per (method, demos, seed): success over all start states and over the paper's first 20."""
    out = []
    for (m, d, s), g in trials.groupby(["method", "demos", "seed"], sort=False):
        g = g.sort_values("trial")
        out.append({"method": m, "demos": int(d), "seed": int(s), "trials": len(g), "successes": int(g.success.sum()),
                    "success_rate": float(g.success.mean()),
                    f"success_rate_first{PAPER_TRIALS}": float(g.success.iloc[:PAPER_TRIALS].mean()),
                    "path_success_rate": float(g.path_success.mean()),
                    "mean_final_box_distance_m": float(g.final_box_distance_m.mean()),
                    "mean_final_yaw_error_rad": float(g.final_yaw_error_rad.mean())})
    return pd.DataFrame(out)


def aggregate(trials: pd.DataFrame) -> pd.DataFrame:
    """Per (method, demos): mean success over seeds and start states, per-seed rates, an interval over both seeds
    and start states, the same on the paper's 20-trial protocol (the first 20 start states), and the paper's; for
    the end-state rule and (columns prefixed ``path_``) the path rule (:data:`CRITERIA`)."""
    out = []
    mats: dict[tuple[str, int], tuple[list, dict[str, np.ndarray]]] = {}
    for (m, d), g in trials.groupby(["method", "demos"], sort=False):
        seeds = sorted(g.seed.unique())
        per = {col: np.array([g[g.seed == s].sort_values("trial")[col].to_numpy(float) for s in seeds])
               for col in CRITERIA}
        if len({len(r) for r in per["success"]}) != 1:
            raise ValueError(f"{m} with {d} demos: seeds were evaluated on different numbers of start states")
        mats[(m, int(d))] = (seeds, per)
    for (m, d), (seeds, per) in mats.items():
        paper = methods.get(m).paper.get(int(d))
        row = {"method": m, "demos": int(d), "start_states": ",".join(sorted(set(trials[
                   (trials.method == m) & (trials.demos == d)].start_states))),
               "seeds": len(seeds), "trials_per_seed": per["success"].shape[1], "trials": int(per["success"].size)}
        base = mats.get((BASELINE, d))
        paired = m != BASELINE and base is not None and base[0] == seeds
        for col, pre in CRITERIA.items():
            mat = per[col]
            lo, hi = seed_state_interval(mat)
            row.update({f"{pre}successes": int(mat.sum()), f"{pre}success_rate": float(mat.mean()),
                        f"{pre}per_seed": ";".join(f"{r:.3f}" for r in mat.mean(axis=1)),
                        f"{pre}ci95_low": lo, f"{pre}ci95_high": hi, f"{pre}worst_seed": float(mat.mean(axis=1).min())})
            if col == "success":
                first = mat[:, :PAPER_TRIALS]
                lo20, hi20 = seed_state_interval(first)
                row.update({f"success_rate_first{PAPER_TRIALS}": float(first.mean()),
                            f"first{PAPER_TRIALS}_ci95_low": lo20, f"first{PAPER_TRIALS}_ci95_high": hi20,
                            "paper_success_rate": float("nan") if paper is None else paper / 100})
            diff = {f"{pre}diff_vs_bc_no_translation": float("nan"), f"{pre}diff_ci95_low": float("nan"),
                    f"{pre}diff_ci95_high": float("nan")}
            if paired:
                diff[f"{pre}diff_vs_bc_no_translation"] = float((mat - base[1][col]).mean())
                diff[f"{pre}diff_ci95_low"], diff[f"{pre}diff_ci95_high"] = paired_difference_interval(
                    mat, base[1][col])
            row.update(diff)
        out.append(row)
    return _ordered(pd.DataFrame(out)).reset_index(drop=True)


PREMISE_TITLE = "Both robots' programs together (premise)"
"""Table I's last row: the demonstrations' robot halves run together in Y (reports/experts.json)."""

BASELINE = "bc_no_translation"
"""The row every other is compared with, paired (the same seeds and start states)."""


def _pct(x: float) -> str:
    return "–" if x != x else f"{100 * x:.1f} %"


def _cell(r, pre: str = "") -> str:
    """A Table I cell: the mean in bold, in brackets the interval and the worst seed (or the per-seed rates)."""
    if r.seeds <= 3:
        per_seed = ", ".join(f"{100 * float(v):.0f}" for v in r[f"{pre}per_seed"].split(";"))
        return (f"**{_pct(r[f'{pre}success_rate'])}** ({per_seed}; {100 * r[f'{pre}ci95_low']:.0f}–"
                f"{100 * r[f'{pre}ci95_high']:.0f})")
    return (f"**{_pct(r[f'{pre}success_rate'])}** ({100 * r[f'{pre}ci95_low']:.0f}–{100 * r[f'{pre}ci95_high']:.0f}; "
            f"worst seed {100 * r[f'{pre}worst_seed']:.0f})")


def markdown(table: pd.DataFrame, premise: dict | None = None) -> str:
    """Table I as markdown: ours on all start states by the end-state rule (per seed, interval) and by the path
    rule, ours on the first 20, the paper's; with ``premise`` (``programs_together_in_Y`` of reports/experts.json) a
    last row: the two pairings' robot halves together, nobody learning."""
    demos = sorted(table.demos.unique())
    head = "| method | " + " | ".join(f"{d} demos: ours | {d}: ours, path rule | {d}: ours, first {PAPER_TRIALS} | "
                                     f"{d}: paper" for d in demos) + " |"
    lines = [head, "| --- |" + " --- | --- | --- | --- |" * len(demos)]
    for m in [m for m in method_order() if m in set(table.method)]:
        cells = []
        for d in demos:
            r = table[(table.method == m) & (table.demos == d)]
            paper = methods.get(m).paper.get(int(d))
            if r.empty:
                cells += ["–", "–", "–", _pct(float("nan") if paper is None else paper / 100)]
                continue
            r = r.iloc[0]
            cells += [_cell(r), _cell(r, "path_"), _pct(r[f"success_rate_first{PAPER_TRIALS}"]),
                      _pct(r.paper_success_rate)]
        lines.append(f"| {methods.get(m).title} | " + " | ".join(cells) + " |")
    if premise is not None:
        lines.append(f"| {PREMISE_TITLE} | " + " | ".join(
            f"{_pct(premise['success_rate'])} | {_pct(premise['path_success_rate'])} | – | –" for _ in demos) + " |")
    n_seeds = int(table.seeds.max())
    per_seed = int(table.trials_per_seed.max())
    block = "" if "start_states" not in table or set(table.start_states) == {"evaluation"} else \
        " **Development start states** (not the evaluation block): for choosing settings, not for reporting."
    bracket = "the per-seed rates in % and " if n_seeds <= 3 else ""
    lines += ["", f"Success rate over {per_seed} start states per seed (the same states for every row), mean over "
              f"{n_seeds} seed(s) (n = {n_seeds * per_seed} trials per cell); in brackets {bracket}"
              "a 95 % interval that counts both the seeds and the start states as random (two-way random effects, "
              f"t with Satterthwaite's degrees of freedom){'' if n_seeds <= 3 else ' and the worst seed'}. "
              "'Ours': the end-state rule (the box centre near the goal, its yaw small and the box at rest). "
              "'Path rule': that, and along the way the box never turned further than its start's |yaw| or the "
              "end-state threshold, whichever is larger, plus a margin (`env.success.path_yaw_margin`): the paper's "
              "task asks the arms to push 'while avoiding the rotation of the box'. "
              f"'First {PAPER_TRIALS}': the paper's protocol "
              f"({PAPER_TRIALS} trials per seed), on the first start states of the same list (end-state rule). "
              "Paper: Kobayashi et al. 2023, Table I. Rows marked (ours) are not in the paper." + block
              + ("" if premise is None else
                 f" '{PREMISE_TITLE}': the two pairings' robot halves together in Y (each robot replays takes of its "
                 f"own program, nobody adapts, nothing is learnt), on {premise['episodes']} development start "
                 f"states; the protocol's premise asks at most {100 * premise['gate']:.0f} % by the path rule.")]
    return "\n".join(lines) + "\n"


def differences_markdown(table: pd.DataFrame) -> str:
    """Each method against BC without translation, paired (the same seeds and start states): the mean difference in
    success and its 95 % interval, per demo count, by the end-state rule and by the path rule."""
    demos = sorted(table.demos.unique())
    rows = [m for m in method_order() if m in set(table.method) and m != BASELINE]
    lines = ["| method | " + " | ".join(f"{d} demos | {d}: path rule" for d in demos) + " |",
             "| --- |" + " --- | --- |" * len(demos)]
    for m in rows:
        cells = []
        for d in demos:
            r = table[(table.method == m) & (table.demos == d)]
            for pre in CRITERIA.values():
                if r.empty or r.iloc[0][f"{pre}diff_vs_bc_no_translation"] != r.iloc[0][
                        f"{pre}diff_vs_bc_no_translation"]:
                    cells.append("–")
                    continue
                x = r.iloc[0]
                cells.append(f"{100 * x[f'{pre}diff_vs_bc_no_translation']:+.1f} "
                             f"({100 * x[f'{pre}diff_ci95_low']:+.1f} to {100 * x[f'{pre}diff_ci95_high']:+.1f})")
        lines.append(f"| {methods.get(m).title} | " + " | ".join(cells) + " |")
    lines += ["", f"Difference from {methods.get(BASELINE).title} in points of success, the same seeds and start "
              "states (paired), with its 95 % interval over both (two-way random effects), by the end-state rule "
              "and by the path rule."]
    return "\n".join(lines) + "\n"


def latex(table: pd.DataFrame) -> str:
    """Table I as a LaTeX tabular (ours / paper per demo count)."""
    demos = sorted(table.demos.unique())
    lines = [r"\begin{tabular}{l" + "rr" * len(demos) + "}", r"\toprule",
             "Method & " + " & ".join(rf"\multicolumn{{2}}{{c}}{{{d} demos}}" for d in demos) + r" \\",
             " & " + " & ".join("ours & paper" for _ in demos) + r" \\", r"\midrule"]
    for m in [m for m in method_order() if m in set(table.method)]:
        cells = []
        for d in demos:
            r = table[(table.method == m) & (table.demos == d)]
            paper = methods.get(m).paper.get(int(d))
            cells += ["--" if r.empty else f"{100 * r.iloc[0].success_rate:.1f}",
                      "--" if paper is None else f"{paper:.1f}"]
        lines.append(f"{methods.get(m).title} & " + " & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}"]
    return "\n".join(lines).replace("%", r"\%") + "\n"


def plot(run_rows: pd.DataFrame, table: pd.DataFrame, path: Path) -> Path:
    """Success rate against demo count: one line per method (mean), its interval as a band, seeds as points,
    the paper's values dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.8, 4.4), dpi=120)
    for m in [m for m in method_order() if m in set(table.method)]:
        meth = methods.get(m)
        t = table[table.method == m].sort_values("demos")
        ax.plot(t.demos, 100 * t.success_rate, "-o", color=meth.colour, label=meth.title)
        ax.fill_between(t.demos, 100 * t.ci95_low, 100 * t.ci95_high, color=meth.colour, alpha=0.08)
        r = run_rows[run_rows.method == m]
        ax.scatter(r.demos + (r.seed - r.seed.mean()) * 2.0, 100 * r.success_rate, color=meth.colour, alpha=0.4, s=16)
        if meth.paper:
            ds = sorted(meth.paper)
            ax.plot(ds, [meth.paper[d] for d in ds], "--", color=meth.colour, alpha=0.5, lw=1)
    ax.set_xlabel("demonstrations per pairing")
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(-3, 103)
    ax.set_xticks(sorted(table.demos.unique()))
    ax.set_title("2D dual-arm box push (dashed: paper's Table I; points: seeds; bands: 95 % intervals)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


CURVE_PANELS = {"loss/dyn": "L_dyn (training batch)", "heldout/selection_loss": "held-out translation loss",
                "D/accuracy": "D's accuracy (training batch)", "loss/adv": "L_adv of G"}
"""The translator's learning-curve columns plotted by :func:`plot_translator_curves`, with their titles."""


def _curve_config(f: Path) -> tuple[str, int]:
    """(method, demos) of a ``<method>-d<demos>_curve.csv`` file."""
    method, demos = f.name[: -len("_curve.csv")].rsplit("-d", 1)
    return method, int(demos)


def plot_translator_curves(translator_dir: Path, path: Path) -> Path:
    """Translator learning curves from reports/translator/*_curve.csv: one panel per CURVE_PANELS column, one
    colour per method, one line style per demo count, each the mean over seeds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = []
    for f in Path(translator_dir).glob("*_curve.csv"):
        method, demos = _curve_config(f)
        curves.append((method_order().index(method), demos, method, f))
    if not curves:
        raise FileNotFoundError(f"no translator learning curves (*_curve.csv) in {translator_dir}")
    styles = ["-", "--", ":", "-."]
    fig, axes = plt.subplots(2, 2, figsize=(12, 6.4), dpi=110, sharex=True)
    demo_counts = sorted({d for _, d, _, _ in curves})
    for _, demos, method, f in sorted(curves):
        curve = pd.read_csv(f)
        meth = methods.get(method)
        for ax, (col, title) in zip(axes.flat, CURVE_PANELS.items()):
            if col not in curve:
                continue
            mean = curve.dropna(subset=[col]).groupby("iteration")[col].mean()
            ax.plot(mean.index, mean.to_numpy(), styles[demo_counts.index(demos) % len(styles)],
                    color=meth.colour, lw=1, label=f"{meth.title}, {demos} demos")
            ax.set_title(title, fontsize=9)
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("iteration")
    axes[0, 0].set_yscale("log")
    axes[0, 1].set_yscale("log")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="center left", bbox_to_anchor=(0.77, 0.5))
    fig.suptitle("Translator learning curves (mean over seeds; the kept checkpoint is the held-out minimum)",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0, 0.77, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def headline(table: pd.DataFrame) -> dict:
    """Table I's success rates as a small nested dict, ``{method: {"d<demos>": rate}}`` (``reports/table1.json``, the
    metrics file `dvc exp show` and `dvc metrics diff` are read with)."""
    out: dict = {}
    for r in table.itertuples():
        out.setdefault(r.method, {})[f"d{r.demos}"] = round(float(r.success_rate), 4)
        out[r.method][f"d{r.demos}_path"] = round(float(r.path_success_rate), 4)
    return out


def success_by_method(table: pd.DataFrame) -> pd.DataFrame:
    """Success rate against demonstrations, one column per method (a DVC plot that overlays the methods)."""
    wide = table.pivot(index="demos", columns="method", values="success_rate")
    return wide[[m for m in method_order() if m in wide]].reset_index()


def curves_by_method(curve_dir: Path, column: str, x: str = "iteration") -> pd.DataFrame:
    """One learning-curve column of every ``<method>-d<demos>_curve.csv`` in ``curve_dir``, one column per method:
    the mean over seeds (and ensemble members) at each demo count, then over demo counts (every method has the same
    ones). A DVC plot of it overlays the methods."""
    per_method: dict[str, list[pd.Series]] = {}
    for f in sorted(Path(curve_dir).glob("*_curve.csv")):
        method, _ = _curve_config(f)
        curve = pd.read_csv(f)
        if column not in curve:
            raise ValueError(f"{f} has no column {column!r}")
        per_method.setdefault(method, []).append(curve.dropna(subset=[column]).groupby(x)[column].mean())
    if not per_method:
        raise FileNotFoundError(f"no learning curves (*_curve.csv) in {curve_dir}")
    wide = pd.DataFrame({m: pd.concat(per_method[m], axis=1).mean(axis=1)
                         for m in method_order() if m in per_method})
    wide.index.name = x
    return wide.reset_index()


DIAGNOSTICS = {
    "selected_iteration": "iteration kept (lowest held-out translation loss)",
    "selected_heldout_loss": "held-out translation loss there",
    "dyn/real_robot": "L_dyn, real robot's columns",
    "dyn/missing_robot": "L_dyn, missing robot's columns",
    "dyn/object": "L_dyn, box's columns",
    "D/accuracy_translated_demos": "D's accuracy on translated demos",
    "D/accuracy_translated_random": "D's accuracy on translated random motion",
    "labels/real_robot_rmse": "F^-1 labels of the real robot vs its recorded actions (RMS)",
    "fk/missing_robot_ee_error_m": "missing arm's end vs FK of its joints (m)",
    "diag/missing_robot_ee_to_hand_m": "missing robot's end to the human's hand (m)",
    "diag/robot_ee_error_m": "real robot's end vs the source (m)",
    "replay_success_rate": "open-loop replay of the labels in Y solves the task",
}
"""Translator diagnostics shown in the README, with their meaning."""


def translator_diagnostics(translator_dir: Path, track_dir: Path | None = None) -> pd.DataFrame:
    """Per (method, demos): the translator diagnostics averaged over seeds (and the re-execution success)."""
    rows = []
    for f in sorted(Path(translator_dir).glob("*.json")):
        d = json.loads(f.read_text())
        seeds = list(d["seeds"].values())
        row = {"method": d["method"], "demos": d["demos"], "seeds": len(seeds)}
        for k in DIAGNOSTICS:
            vals = [s[k] for s in seeds if isinstance(s.get(k), int | float)]
            row[k] = float(np.mean(vals)) if vals else float("nan")
        rows.append(row)
    if track_dir is not None:
        for f in sorted(Path(track_dir).glob("*.json")):
            d = json.loads(f.read_text())
            seeds = list(d["seeds"].values())
            rows.append({"method": d["method"], "demos": d["demos"], "seeds": len(seeds),
                         "execution_success_rate": float(np.mean([s["execution_success_rate"] for s in seeds]))})
    if not rows:
        raise FileNotFoundError(f"no translator reports in {translator_dir}")
    return _ordered(pd.DataFrame(rows)).reset_index(drop=True)


def stage_times(bookkeeping: Mapping[str, Iterable[Path]]) -> pd.DataFrame:
    """Wall time of every stage run that produced the current reports, summed per stage, from the stages'
    bookkeeping files (``runs/``), given per stage name."""
    rows = []
    for name, files in bookkeeping.items():
        walls = []
        for f in files:
            d = json.loads(Path(f).read_text())
            w = d.get("stage_wall_s", d.get("job_wall_s", d.get("wall_time_s")))
            if w is not None:
                walls.append(float(w))
        if name == "train_experts" and walls:
            walls = [max(walls)]  # both pairings train side by side in one stage
        if walls:
            rows.append({"stage": name, "runs": len(walls), "total_s": sum(walls), "mean_s": float(np.mean(walls))})
    return pd.DataFrame(rows)
