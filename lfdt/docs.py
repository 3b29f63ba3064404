"""The numbers in the README and in docs/, written from reports/ and benchmarks/results/ (never by hand).

A page holds generated blocks between ``<!-- generated:NAME -->`` and ``<!-- /generated:NAME -->``; this module
renders each block from the files it names and puts it in place. ``python -m lfdt.docs`` rewrites the pages
(``make docs``); ``python -m lfdt.docs --check`` exits 1 naming every block that differs from what the reports say
(``tests/test_docs.py`` runs it, so a page can never disagree with its reports).
"""

from __future__ import annotations

import argparse
import csv
import io
import re
import statistics
import sys
from collections.abc import Callable
from pathlib import Path

from lfdt import inputs, methods
from lfdt.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
PAGES = ("README.md", "docs/results.md", "docs/experiments.md", "docs/benchmarks.md")
"""The pages that hold generated blocks."""


EXPECTED = "the file the pipeline (or the tool that writes it) wrote: run it again, or `git checkout -- FILE`"
"""What every report the pages are written from must be (the one line of a refusal ends with it)."""


def _read_text(path: Path) -> str:
    """A report's UTF-8 text; a missing, unreadable or not-UTF-8 file is an InputError naming it."""
    return inputs.read_text(path, "report", EXPECTED)


def _read_json(path: Path) -> dict:
    """A report's JSON object (:func:`lfdt.inputs.json_object`: empty, cut-short or not-an-object files named)."""
    return inputs.json_object(path, "report", EXPECTED)


def _read_rows(path: Path, columns: tuple[str, ...] = (), empty_ok: bool = False) -> list[dict[str, str]]:
    """A CSV report's rows (at least one, unless ``empty_ok``) as dicts of its header's columns, which include
    ``columns``. A row with more or fewer fields than the header (a file cut short mid-row, a stray comma), a header
    without rows or without a column a block reads is an InputError naming the file: a partial report must never
    become a partial table on a page."""
    reader = csv.reader(io.StringIO(_read_text(path)))
    header = next(reader, None)
    if not header:
        raise InputError(f"report {path}: has no header line; expected {EXPECTED}")
    missing = [c for c in columns if c not in header]
    if missing:
        raise InputError(f"report {path}: its header has no column {', '.join(map(repr, missing))}; expected "
                         f"{EXPECTED}")
    rows = []
    for row in reader:
        if not row:
            continue
        if len(row) != len(header):
            raise InputError(f"report {path}, line {reader.line_num}: {len(row)} fields where its header has "
                             f"{len(header)} (cut short?); expected {EXPECTED}")
        rows.append(dict(zip(header, row)))
    if not rows and not empty_ok:
        raise InputError(f"report {path}: holds a header and no rows; expected {EXPECTED}")
    return rows


def table1(root: Path) -> str:
    """Table I and the paired differences, as the report stage wrote them (reports/table1.md)."""
    return _read_text(root / "reports" / "table1.md").strip()


TABLE1_COLUMNS = ("method", "demos", "success_rate", "worst_seed", "ci95_low", "ci95_high", "diff_vs_bc_no_translation",
                  "diff_ci95_low", "diff_ci95_high")
"""The columns of reports/table1.csv the headline reads (the path rule's, ``path_*``, only where the report has them:
reports of earlier versions lack them)."""


def headline(root: Path) -> str:
    """LfDT and BC without translation in one sentence per demo count and success rule, from reports/table1.csv."""
    rows = _read_rows(root / "reports" / "table1.csv", TABLE1_COLUMNS)
    by = {(r["method"], int(r["demos"])): r for r in rows}
    sentences = []
    for pre, rule in (("", "end-state rule"), ("path_", "path rule")):
        parts = []
        verdict: dict[str, list[str]] = {"better": [], "worse": [], "not different": []}
        for d in sorted({int(r["demos"]) for r in rows}):
            a, b = by.get(("lfdt", d)), by.get(("bc_no_translation", d))
            if a is None or b is None or f"{pre}success_rate" not in a:
                continue
            lo, hi = float(a[f"{pre}diff_ci95_low"]), float(a[f"{pre}diff_ci95_high"])
            verdict["better" if lo > 0 else "worse" if hi < 0 else "not different"].append(str(d))
            pct = {k: 100 * float(a[pre + k]) for k in ("success_rate", "worst_seed", "ci95_low", "ci95_high",
                                                         "diff_vs_bc_no_translation", "diff_ci95_low",
                                                         "diff_ci95_high")}
            parts.append(f"{d} demos: LfDT **{pct['success_rate']:.1f} %** (worst seed {pct['worst_seed']:.0f} %, "
                         f"interval {pct['ci95_low']:.0f}–{pct['ci95_high']:.0f}), BC without translation "
                         f"{100 * float(b[pre + 'success_rate']):.1f} %, difference "
                         f"{pct['diff_vs_bc_no_translation']:+.1f} points ({pct['diff_ci95_low']:+.1f} to "
                         f"{pct['diff_ci95_high']:+.1f})")
        if not parts:
            continue
        said = "; ".join(f"{k} at {', '.join(v)} demos" for k, v in verdict.items() if v)
        sentences.append(f"By the {rule}: " + "; ".join(parts) + ". LfDT against BC without translation (the "
                         f"paper's finding is 'better' at every demo count), judged by whether the paired interval "
                         f"excludes 0: {said}.")
    return (f"Over {rows[0]['seeds']} training seeds x {rows[0]['trials_per_seed']} evaluation start states per cell. "
            + " ".join(sentences))


def cross_cpu(root: Path) -> str:
    """Where the committed fingerprint was reproduced (reports/cross_cpu.json, reports/fingerprint.json)."""
    doc = _read_json(root / "reports" / "cross_cpu.json")
    fp = _read_json(root / "reports" / "fingerprint.json")
    lines = ["| CPU (as /proc/cpuinfo or QEMU names it) | vector ISA | numerics | same bits as the committed "
             "fingerprint |", "| --- | --- | --- | --- |"]
    for host in [doc, *doc.get("earlier_hosts", [])]:
        when = "" if host is doc else f", {host['date']}"
        for r in host["runs"]:
            if r["emulated_model"]:
                cpu, isa = f"QEMU `-cpu {r['emulated_model']}` on {host['host_cpu_model']}{when}", "AVX2 (emulated)"
            else:
                cpu = host["host_cpu_model"] + when
                isa = host["host_cpu_isa"].upper().replace("AVX512", "AVX-512")
            n_same = sum(r["matches_committed"].values())
            verdict = f"yes, all {len(r['matches_committed'])} components compared" if r["all_match"] else \
                f"no ({n_same}/{len(r['matches_committed'])} components)"
            lines.append(f"| {cpu} | {isa} | {r['numerics']} | {verdict} |")
    libs = ", ".join(f"{k} {v}" for k, v in sorted(fp["versions"].items()))
    compared = sorted({k for r in doc["runs"] for k in r["matches_committed"]})
    later = sorted(set(fp["components"]) - set(compared))
    qemu = f" ({doc['qemu']})" if doc.get("qemu") else ""  # a run without emulated CPUs names no QEMU
    lines += ["", f"Measured {doc['date']} with `python tools/cross_cpu.py`{qemu}; components "
              f"{', '.join(compared)}; libraries {libs}."
              + "".join(f" The rows dated {e['date']} ran on {e['host_cpu_model']} against the fingerprint of then "
                        f"({len(e['committed'])} components: {', '.join(sorted(e['committed']))})."
                        for e in doc.get("earlier_hosts", []))
              + (f" Added to the fingerprint since, not yet run on these CPUs: {', '.join(later)} (`make cross-cpu`)."
                 if later else "")]
    return "\n".join(lines)


def run_time(root: Path) -> str:
    """The full pipeline's wall time per stage (reports/stage_times.csv) and in all (reports/run_time.json)."""
    doc = _read_json(root / "reports" / "run_time.json")
    rows = _read_rows(root / "reports" / "stage_times.csv", ("stage", "runs", "total_s"))
    lines = ["| stage | runs | minutes |", "| --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {r['stage']} | {r['runs']} | {float(r['total_s']) / 60:.1f} |")
    stages_min = sum(float(r['total_s']) for r in rows) / 60
    where = f"{doc['cpu_model']} ({doc['cores']} cores, {doc['date']}, commit {doc['commit'][:7]})"
    if doc.get("minutes") is None:  # a run that was not timed in one piece says so, never an estimate
        lines += ["", f"The committed run on {where}: {doc['how']}. Its wall time was not measured in one piece; "
                      f"the stages' own processes sum to **{stages_min:.1f} min**."]
    else:
        lines += ["", f"A full `dvc repro` from a clean clone took **{doc['minutes']:.1f} min** on {where}; the "
                      f"stages' own processes sum to {stages_min:.1f} min, the rest is DVC's."]
    return "\n".join(lines)


def run_time_line(root: Path) -> str:
    """One sentence: how long the committed run took, where (reports/run_time.json)."""
    doc = _read_json(root / "reports" / "run_time.json")
    setup = "" if doc.get("setup_minutes") is None else f", after {doc['setup_minutes']:.1f} min of `make setup`"
    if doc.get("minutes") is None:
        return (f"The committed results were computed on {doc['cpu_model']} with {doc['cores']} cores, {doc['date']} "
                f"({doc['how']}); that run's wall time was not measured in one piece (per stage: "
                "[docs/results.md](docs/results.md#run-time)).")
    return (f"The committed results took **{doc['minutes']:.0f} min** of `dvc repro` ({doc['how']}{setup}) on "
            f"{doc['cpu_model']} with {doc['cores']} cores, {doc['date']}.")


def twin(root: Path) -> str:
    """The twin's results as its report stage wrote them (reports/twin.md), headings one level down."""
    text = _read_text(root / "reports" / "twin.md").strip()
    return re.sub(r"(?m)^#", "##", text)


def translator_diagnostics(root: Path) -> str:
    """The translator diagnostics per (method, demos), from reports/translator_diagnostics.csv."""
    from lfdt.report import DIAGNOSTICS

    rows = _read_rows(root / "reports" / "translator_diagnostics.csv", ("method", "demos", "selected_iteration"))
    rows = [r for r in rows if r.get("selected_iteration")]
    head = "| diagnostic | " + " | ".join(f"{r['method']} d{r['demos']}" for r in rows) + " |"
    lines = [head, "| --- |" + " --- |" * len(rows)]
    for key, meaning in DIAGNOSTICS.items():
        vals = []
        for r in rows:
            v = r.get(key, "")
            vals.append("–" if v in ("", "nan") else f"{float(v):.4g}")
        lines.append(f"| {meaning} | " + " | ".join(vals) + " |")
    return "\n".join(lines)


def benchmarks(root: Path) -> str:
    """Speed ratios from benchmarks/results/ (stack_throughput.json, pin_cost.json and pin_cost_*.json of other
    CPUs, worker_start.json, optimizer_start.json)."""
    res = root / "benchmarks" / "results"
    lines = ["| benchmark | ours | baseline | ratio | goal |", "| --- | --- | --- | --- | --- |"]
    st = _read_json(res / "stack_throughput.json")
    for name in ("translator", "bc", "evaluate"):
        r = st[name]
        lines.append(f"| {name}: {st['seeds']} seeds stacked vs one at a time ({r['unit']}/s, one core) | "
                     f"{r['per_s']['stacked']:.0f} | {r['per_s']['one_at_a_time']:.0f} | **{r['speedup']:.2f}** | 4 |")
    pc = _read_json(res / "pin_cost.json")
    # the same measure on other CPUs (pin_cost_*.json) after the main one, each row naming its CPU
    for doc, where in [(pc, ""), *((o, f" on {o['cpu_model']} ({o['cpu_isa'].upper()}, {o['date']})")
                                   for o in map(_read_json, sorted(res.glob("pin_cost_*.json"))))]:
        for name, r in doc.items():  # benchmarks/pin_cost.py's workloads, in its order
            if isinstance(r, dict) and "ratio_pinned_over_native" in r:
                lines.append(f"| {name}: pinned vs `LFDT_NUMERICS=native`{where} (/s) | {r['per_s']['pinned']:.0f} | "
                             f"{r['per_s']['native']:.0f} | **{r['ratio_pinned_over_native']:.2f}** | |")
    ws = _read_json(res / "worker_start.json")
    med = ws["median"]
    lines.append(f"| a stage's two workers: spawn vs forkserver, whole stage process (s, wall; lower is better) | "
                 f"{med['forkserver']['wall_s']:.1f} | {med['spawn']['wall_s']:.1f} | "
                 f"**{ws['ratio_wall_spawn_over_forkserver']:.2f}** | |")
    if "forkserver_bare" in med:  # results of benchmarks/worker_start.py since 2026-12-07
        lines.append(f"| the same, CPU of the process tree (s; lower is better) | {med['forkserver']['cpu_s']:.1f} | "
                     f"{med['spawn']['cpu_s']:.1f} | **{ws['ratio_cpu_spawn_over_forkserver']:.2f}** | |")
        for unit, key in (("wall", "wall_s"), ("CPU of the process tree", "cpu_s")):
            lines.append(f"| a stage's two workers: a forkserver preloading nothing (Python 3.11's default) vs "
                         f"lfdt.parallel's (s, {unit}; lower is better) | {med['forkserver'][key]:.1f} | "
                         f"{med['forkserver_bare'][key]:.1f} | "
                         f"**{ws['ratio_' + key.split('_')[0] + '_bare_over_forkserver']:.2f}** | |")
    if ws.get("smoke_runs"):
        sm = {m: statistics.median(ws["smoke"][m]["wall_s"]) for m in ("spawn", "forkserver")}
        lines.append(f"| the smoke DAG's `dvc repro`: spawn vs forkserver (s, wall; lower is better) | "
                     f"{sm['forkserver']:.0f} | {sm['spawn']:.0f} | "
                     f"**{ws['smoke_ratio_wall_spawn_over_forkserver']:.2f}** | |")
    sa_path = res / "smoke_against.json"
    sa = _read_json(sa_path) if sa_path.exists() else None
    if sa:
        sm = sa["median"]
        for unit, key in (("wall", "wall_s"), ("CPU of the process tree", "cpu_s")):
            lines.append(f"| the smoke DAG's `dvc repro --force`: this code vs commit {sa['against']} (s, {unit}; "
                         f"lower is better) | {sm['working tree'][key]:.0f} | {sm[sa['against']][key]:.0f} | "
                         f"**{sa['ratio_' + key.split('_')[0] + '_against_over_working_tree']:.2f}** | |")
    os_ = _read_json(res / "optimizer_start.json")
    med = os_["median"]
    lines.append(f"| a training process to its first optimizer step: torch's compiler imported (as torch's optimizer "
                 f"wrapping did) vs not (s, CPU; lower is better) | {med['without_compiler']['cpu_s']:.2f} | "
                 f"{med['with_compiler']['cpu_s']:.2f} | **{os_['ratio_cpu_with_over_without']:.2f}** | |")
    same = "yes" if sa and all(sa["identical_outputs"].values()) else "NO"
    lines += ["", f"Stacking: {st['cpu_model']}, {st['date']}, medians of {st['repeats']}. Pin: {pc['cpu_model']} "
              f"({pc['cpu_isa'].upper()}), {pc['date']}, medians of {pc['repeats']}; on other CPUs where named. "
              f"Workers' start: {ws['cpu_model']}, {ws['date']}, medians of "
              f"{ws['repeats']}" + (f" (smoke DAG: {ws['smoke_runs']} run each way)" if ws.get("smoke_runs") else "")
              + "; ratio = spawn's (or the bare server's) time / lfdt.parallel's forkserver's. "
              + (f"Smoke DAG against {sa['against']}: {sa['cpu_model']}, {sa['date']}, {sa['repeats']} run(s) each "
                 f"way, alternately; outputs the same bits: {same}. "
                 if sa else "") +
              f"Optimizer start: {os_['cpu_model']}, {os_['date']}, medians of {os_['repeats']} processes each way; "
              f"ratio = with the compiler / without."]
    return "\n".join(lines)


ABLATION_TRIALS = ("bcseed-0", "ablation-no-id", "ablation-no-id-translate-box", "ablation-no-dyn",
                   "ablation-no-dyn-paper-d")
"""The development trials that explain the ablation rows (docs/results.md, Ablations)."""


def ablations(root: Path) -> str:
    """The ablation trials' rows of docs/experiments/trials.csv, with the diagnostics that explain them."""
    return experiments(root, only=ABLATION_TRIALS, diagnostics=("diag/robot_ee_error_m",
                                                                 "diag/missing_robot_ee_to_hand_m"))


ABLATION_VARIANTS = {"lfdt_no_id": ("ablation-no-id", "ablation-no-id-translate-box",
                                   "the box copied from X", "G translating the box as the paper's does"),
                     "lfdt_no_dyn": ("ablation-no-dyn", "ablation-no-dyn-paper-d",
                                     "our D (robots' columns of translated random motion)",
                                     "the paper's D (every column of every translated transition)")}
"""Ablation method -> (its development trial with our translator, the paper-faithful variant's trial, what ours
does, what the paper's does)."""


def ablation_caption(root: Path) -> str:
    """Table I's caption for the ablation rows: where ours deviates and the paper-faithful variant's number."""
    rows = {r["trial"]: r for r in _read_rows(root / "docs" / "experiments" / "trials.csv")}
    parts = []
    for method, (ours, paper, ours_is, paper_is) in ABLATION_VARIANTS.items():
        a, b = rows[ours], rows[paper]
        parts.append(f"**{methods.get(method).title}** is our translator with one loss weight at 0, {ours_is}; on "
                     f"the development seeds at {a['demos']} demonstrations it succeeds {a['success_pct']} % "
                     f"(worst seed {a['worst_seed_pct']} %), with {paper_is} {b['success_pct']} % (worst seed "
                     f"{b['worst_seed_pct']} %)")
    used = [rows[trial] for ours, paper, _, _ in ABLATION_VARIANTS.values() for trial in (ours, paper)]
    cpus = sorted({r["cpu_model"] for r in used})
    dates = sorted({r["date"] for r in used})
    when = dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}"
    why = "[docs/results.md](docs/results.md#ablations-why-ours-are-not-the-papers)"
    return ("Deviations of the ablation rows: " + "; ".join(parts) + f" ({', '.join(cpus)}, "
            f"{when}; why: {why}).")


def experiments(root: Path, only: tuple[str, ...] | None = None, diagnostics: tuple[str, ...] = ()) -> str:
    """Every development trial (docs/experiments/trials.csv), one row per trial and method (``only``: those trials,
    in that order, with the mean over seeds of each of ``diagnostics`` from the trial's seeds file)."""
    path = root / "docs" / "experiments" / "trials.csv"
    rows = _read_rows(path)
    if only is not None:
        rows = sorted((r for r in rows if r["trial"] in only), key=lambda r: only.index(r["trial"]))
        rows = [r for r in rows if r["method"] != "bc_no_translation" or r["trial"] == only[0]]
    extra = "".join(f" {d} |" for d in diagnostics)
    head = ("| trial | change | method | demos | success | 95 % interval | worst seed | vs BC w/o translation | "
            "path rule (worst seed) | path rule: vs BC w/o |")
    lines = [head + extra,
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |" + " --- |" * len(diagnostics)]

    def diff(r: dict, pre: str = "") -> str:
        d = r.get(f"{pre}diff_vs_bc_no_translation_pct")
        return f"{d} ({r[f'{pre}diff_ci_low_pct']} to {r[f'{pre}diff_ci_high_pct']})" if d else "–"

    for r in rows:
        path = f"{r['path_success_pct']} % ({r['path_worst_seed_pct']} %)" if r.get("path_success_pct") else "–"
        diag = "".join(f" {_seed_mean(root, r['trial'], r['method'], d)} |" for d in diagnostics)
        lines.append(f"| {r['trial']} | {r['changes'] or '(none)'} | {r['method']} | {r['demos']} | "
                     f"{r['success_pct']} % | {r['ci_low_pct']}–{r['ci_high_pct']} | {r['worst_seed_pct']} % | "
                     f"{diff(r)} | {path} | {diff(r, 'path_')} |" + diag)
    cpus = sorted({f"{r['cpu_model']} ({r['numerics']})" for r in rows})
    dates = sorted({r["date"] for r in rows})
    lines += ["", f"Development seeds {rows[0]['seeds'] if rows else ''}, development start states (200 per seed); "
              f"{', '.join(cpus)}; {dates[0] if dates else ''} to {dates[-1] if dates else ''}."]
    return "\n".join(lines)


BC_SEED_TRIALS = {0: "bcseed-0", 1000: "bcseed-1000", 2000: "bcseed-2000", 3000: "bcseed-3000", 4000: "bcseed-4000"}
"""BC seed offset -> the development trial that trained BC with it on the baseline's data."""
ENSEMBLES = {"lfdt": "ens5-lfdt", "bc_no_translation": "ens5-bc-no-translation"}
"""Method -> the trial of its five BC seeds' mean action."""


def _outcome_rows(root: Path, trial: str, method: str, demos: int | str = 100) -> dict[int, list[int]] | None:
    """A development trial's 0/1 outcomes by seed (docs/experiments/outcomes/, the end-state rule), None if none."""
    path = root / "docs" / "experiments" / "outcomes" / f"{trial}_{method}-d{demos}.csv"
    if not path.exists():
        return None
    return {int(r["seed"]): [int(c) for c in r["outcomes"]] for r in _read_rows(path)}


def _outcomes(root: Path, trial: str, method: str, demos: int = 100) -> dict[int, float]:
    rows = _outcome_rows(root, trial, method, demos)
    if rows is None:
        raise FileNotFoundError(f"no outcomes of trial {trial} ({method}, {demos} demonstrations) in docs/experiments")
    return {seed: sum(o) / len(o) for seed, o in rows.items()}


def bc_seed_spread(root: Path) -> str:
    """Per development seed: success with each of five BC seeds on the same data, and with their mean action."""
    lines = []
    for method, ens in ENSEMBLES.items():
        per = {off: _outcomes(root, t, method) for off, t in BC_SEED_TRIALS.items()}
        mean_of = _outcomes(root, ens, method)
        seeds = sorted(per[0])
        lines += [f"**{method}** (100 demonstrations; success in % per seed)", "",
                  "| BC seed | " + " | ".join(str(s) for s in seeds) + " | mean |",
                  "| --- |" + " --- |" * (len(seeds) + 1)]
        for off, rates in per.items():
            row = [rates[s + off] if s + off in rates else rates[s] for s in seeds]
            lines.append(f"| seed + {off} | " + " | ".join(f"{100 * r:.0f}" for r in row) +
                         f" | {100 * sum(row) / len(row):.1f} |")
        row = [mean_of[s] for s in seeds]
        lines.append("| mean action of the five | " + " | ".join(f"**{100 * r:.0f}**" for r in row) +
                     f" | **{100 * sum(row) / len(row):.1f}** |")
        lines.append("")
    return "\n".join(lines).rstrip()


def _seed_mean(root: Path, trial: str, method: str, key: str) -> str:
    """The mean over seeds of a translator diagnostic of a trial (its seeds file), or '–'."""
    path = root / "docs" / "experiments" / f"{trial}_seeds.csv"
    if not path.exists():
        return "–"
    translator = methods.get(method).translator
    vals = [float(r[key]) for r in _read_rows(path)
            if r.get("stage") == "translator" and r.get("method") == translator and r.get(key) not in (None, "")]
    return f"{sum(vals) / len(vals):.4g}" if vals else "–"


ISSUE37_PREFIX = "i37-"
"""The development trials of issue 37 (a demonstration protocol that needs coordination, a translator without its
shared sideways bias): their table in docs/experiments.md shows the diagnostics each hypothesis is about."""


def issue37(root: Path) -> str:
    """Issue 37's development trials, both success rules, with what they were about: how far the replacing robot
    pushes further out across the box than the hand did, its distance to the hand, the open-loop replay of the
    labels, and F's error on two-arm pushes across the box and in yaw (a share of predicting no change)."""
    rows = [r for r in _read_rows(root / "docs" / "experiments" / "trials.csv")
            if r["trial"].startswith(ISSUE37_PREFIX) and not _in_a_search(root, r["trial"])
            and r["trial"] not in {t for pair in CONFIRMATIONS for t in pair}]
    lines = ["| trial | change | method | demos | success (worst seed) | path rule (worst seed) | path rule: vs BC "
             "w/o | replacing robot further out than the hand (cm) | replacing robot to the hand (cm) | replay of the "
             "labels solves | F on pushes: across / yaw |", "| --- |" + " --- |" * 10]

    def mean(r: dict, key: str, scale: float = 1.0, fmt: str = ".2f") -> str:
        v = _seed_mean(root, r["trial"], r["method"], key)
        return "–" if v == "–" else f"{scale * float(v):{fmt}}"

    for r in rows:
        d = r.get("path_diff_vs_bc_no_translation_pct")
        diff = f"{d} ({r['path_diff_ci_low_pct']} to {r['path_diff_ci_high_pct']})" if d else "–"
        f_push = f"{r['f_push_across']} / {r['f_push_angle']}" if r.get("f_push_across") else "–"
        pct = "" if mean(r, "replay_success_rate") == "–" else " %"
        lines.append(f"| {r['trial']} | {r['changes'] or '(none)'} | {r['method']} | {r['demos']} | "
                     f"{r['success_pct']} % ({r['worst_seed_pct']} %) | {r['path_success_pct']} % "
                     f"({r['path_worst_seed_pct']} %) | {diff} | {mean(r, 'diag/missing_minus_hand_across_m', 100)} | "
                     f"{mean(r, 'diag/missing_robot_ee_to_hand_m', 100)} | "
                     f"{mean(r, 'replay_success_rate', 100, '.0f')}{pct} | "
                     f"{f_push} |")
    cpus = sorted({f"{r['cpu_model']} ({r['numerics']})" for r in rows})
    dates = sorted({r["date"] for r in rows})
    lines += ["", f"Development seeds {rows[0]['seeds'] if rows else ''}, development start states (200 per seed); "
              f"{', '.join(cpus)}; {dates[0] if dates else ''} to {dates[-1] if dates else ''}. Diagnostics are means "
              "over the seeds' translators; BC without translation's rows have none."]
    return "\n".join(lines)


PROBE_VARIANTS = {"clones": "both clones (BC without translation as evaluated)",
                  "clone1+program2": "Robot1's clone beside Robot2's program",
                  "program1+clone2": "Robot1's program beside Robot2's clone",
                  "yaw-frozen": "both clones, the box yaw they see held at its start value",
                  "yaw-zero": "both clones, the box yaw they see at 0"}
"""The variants of tools/probe_halves.py, as the docs name them."""


def probe_halves(root: Path) -> str:
    """BC without translation's cloned robot halves probed (docs/experiments/probe_halves_*.json)."""
    lines = ["| trial | demos | variant | end-state rule | path rule | path rule per seed |",
             "| --- | --- | --- | --- | --- | --- |"]
    docs = [_read_json(f) for f in sorted((root / "docs" / "experiments").glob("probe_halves_*.json"))]
    for d in docs:
        for k, v in d["variants"].items():
            lines.append(f"| {d['trial']} | {d['demos']} | {PROBE_VARIANTS.get(k, k)} | {v['end_pct']} % | "
                         f"{v['path_pct']} % | {', '.join(f'{x:.0f}' for x in v['per_seed_path_pct'])} |")
    if docs:
        lines += ["", f"Development seeds {', '.join(map(str, docs[0]['seeds']))}, {docs[0]['trials_per_seed']} "
                  f"development start states per seed; {docs[0]['cpu_model']}, {docs[0]['date']} "
                  "(`python tools/probe_halves.py`)."]
    return "\n".join(lines)


def load_test(root: Path) -> str:
    """What the load test found on each store (reports/load.json, written by tools/load_test.py)."""
    docs = _read_json(root / "reports" / "load.json")
    first = next(iter(docs.values()))
    lines = [f"Load test (`python tools/load_test.py`): {first['sweeps']} sweeps at once, each "
             f"{first['points_per_sweep']} points of {first['workers_per_point']} stage processes at once "
             f"({first['metrics_per_run']} metric curves of {first['steps_per_metric']} steps per run), while the "
             f"MLflow UI serves runs-table and chart requests; {first['cpu_model']} with {first['cores']} cores, "
             f"{first['date']}.", "", "| store | runs in the store | metric rows in the store | lost | UI requests "
             "| UI errors | UI median / 95th percentile | wall |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for d in docs.values():
        lost = "nothing" if not d["problems"] else f"**{len(d['problems'])} problems**"
        lines.append(f"| {d['how']} | {d['runs_found']} of {d['runs_logged']} | {d['metric_rows_found']:,} of "
                     f"{d['metric_rows_logged']:,} | {lost} | {d['ui_requests']} | {d['ui_errors']} | "
                     f"{d['ui_p50_ms']:.0f} / {d['ui_p95_ms']:.0f} ms | {d['wall_s']:.0f} s |")
    return "\n".join(lines)


def _in_a_search(root: Path, trial: str) -> bool:
    """Whether ``trial`` is one of a ``tools/dev_search.py`` study's (``<study>-t<n>``, the study having its
    docs/experiments/search_<study>.csv): those have a block of their own (:func:`search`)."""
    studies = [p.stem[len("search_"):] for p in (root / "docs" / "experiments").glob("search_*.csv")]
    return any(re.fullmatch(rf"{re.escape(s)}-t\d+", trial) for s in studies)


def search(root: Path) -> str:
    """Each study of ``tools/dev_search.py`` (docs/experiments/search_<study>.csv): every finished trial with its knobs
    and outcomes, and the best trial's paired difference from the baseline trial (the same seeds and start states)."""


    trials = {r["trial"]: r for r in _read_rows(root / "docs" / "experiments" / "trials.csv")
              if r["method"] == "lfdt"}
    out = []
    for path in sorted((root / "docs" / "experiments").glob("search_*.csv")):
        study = path.stem[len("search_"):]
        rows = _read_rows(path, empty_ok=True)  # a study whose first trial has not finished yet
        if not rows:
            continue
        knobs = [k for k in rows[0] if k.startswith("translator.")]
        out += [f"**{study}**", "", "| trial | " + " | ".join(k.split(".", 1)[1] for k in knobs) +
                " | success (worst seed) | path rule (worst seed) | per seed | wall (min) |",
                "| --- |" + " --- |" * (len(knobs) + 4)]
        first_row = next((r for r in rows if r.get("baseline") == "True"), None) if "baseline" in rows[0] else \
            next((r for r in rows if r["trial"] == "0"), None)
        for r in sorted(rows, key=lambda r: int(r["trial"])):
            label = f"t{r['trial']}" + (" (params.yaml)" if r is first_row else "") + \
                (f" (= t{r['repeat_of']}, not run again)" if r.get("repeat_of") else "")
            out.append(f"| {label} | " + " | ".join(r[k] for k in knobs) + f" | {r['success_pct']} % "
                       f"({r['worst_seed_pct']} %) | {r['path_success_pct']} % ({r['path_worst_seed_pct']} %) | "
                       f"{r['per_seed_pct']} | {r['wall_min']} |")
        b = first_row["trial"] if first_row else None
        first = trials.get(f"{study}-t{b}") if b is not None else None
        run = [r for r in rows if not r.get("repeat_of")]
        best = max(run, key=lambda r: (float(r["success_pct"]), -int(r["trial"])))
        demos = first["demos"] if first else ""
        base = _outcome_rows(root, f"{study}-t{b}", "lfdt", demos) if first else None
        top = _outcome_rows(root, f"{study}-t{best['trial']}", "lfdt", demos)
        line = f"Best of {len(run)} trials: t{best['trial']}, {best['success_pct']} %"
        paired = _paired(top, base) if best is not first_row else None
        if paired:
            mean, lo, hi = paired
            line += (f"; against t{b} (params.yaml), paired over the same seeds and start states: "
                     f"{mean:+.1f} points (95 % interval {lo:+.1f} to {hi:+.1f}), "
                     f"an interval that does not allow for having picked the best of {len(run)}")
        if first:
            names = [f"{study}-t{r['trial']}" for r in rows]
            dates = sorted({trials[n]["date"] for n in names if n in trials})
            line += (f". LfDT at {demos} demonstrations, development seeds {first['seeds']}, development start "
                     f"states; {first['cpu_model']} ({first['numerics']}), {dates[0]} to {dates[-1]}.")
        out += ["", line, ""]
    return "\n".join(out).rstrip()


CONFIRMATIONS: tuple[tuple[str, str], ...] = (
    ("i37-confirm-d50-t13", "i37-confirm-d50-t0"),
    ("i37-confirm-d200-t13", "i37-confirm-d200-t0"),
    ("i37-confirm-d50-side0", "i37-confirm-d50-t0"),
    ("i37-confirm-d200-side0", "i37-confirm-d200-t0"),
)
"""(candidate, baseline) development trials that confirm a search's pick on development seeds the search did not use;
their names and hypotheses written (tools/dev_trial.py --hypothesis, trials.csv) before they ran."""


def _paired(top: dict[int, list[int]] | None, base: dict[int, list[int]] | None) -> tuple[float, float, float] | None:
    """``top`` - ``base`` in points of success over the same seeds and start states (0/1 outcomes by seed), with its
    95 % interval (:func:`lfdt.evaluation.paired_difference_interval`); None unless both ran on the same seeds."""
    import numpy as np

    from lfdt.evaluation import paired_difference_interval

    if top is None or base is None or sorted(top) != sorted(base):
        return None
    top, base = (np.array([r[s] for s in sorted(r)], dtype=float) for r in (top, base))
    lo, hi = paired_difference_interval(top, base)
    return 100 * (top - base).mean(), 100 * lo, 100 * hi


def _cm(root: Path, trial: str) -> str:
    v = _seed_mean(root, trial, "lfdt", "diag/missing_minus_hand_across_m")
    return "–" if v == "–" else f"{100 * float(v):.2f}"


def confirm(root: Path) -> str:
    """Each pair of :data:`CONFIRMATIONS` that has run: both trials' success by both rules, and the candidate's paired
    difference from the baseline over the same seeds and start states, with its 95 % interval."""


    trials = {r["trial"]: r for r in _read_rows(root / "docs" / "experiments" / "trials.csv")
              if r["method"] == "lfdt"}
    lines = ["| candidate | baseline | demos | seeds | candidate: success (worst seed) | baseline: success (worst "
             "seed) | difference (95 % interval) | path rule: difference (95 % interval) | replacing robot further out "
             "than the hand (cm): candidate / baseline |", "| --- |" + " --- |" * 8]
    ran = [(c, b) for c, b in CONFIRMATIONS if c in trials and b in trials]
    for cand, base in ran:
        c, b = trials[cand], trials[base]
        diffs = []
        for suffix in ("", "_path"):
            paired = _paired(*(_outcome_rows(root, t, "lfdt", f"{r['demos']}{suffix}") for t, r in ((cand, c),
                                                                                                   (base, b))))
            diffs.append("{:+.1f} ({:+.1f} to {:+.1f})".format(*paired) if paired else "–")
        lines.append(f"| {cand} ({c['changes'] or 'params.yaml'}) | {base} ({b['changes'] or 'params.yaml'}) | "
                     f"{c['demos']} | {c['seeds']} | {c['success_pct']} % ({c['worst_seed_pct']} %) | "
                     f"{b['success_pct']} % ({b['worst_seed_pct']} %) | {diffs[0]} | {diffs[1]} | "
                     f"{_cm(root, cand)} / {_cm(root, base)} |")
    if not ran:
        return "No confirmation has run yet."
    cpus = sorted({f"{trials[t]['cpu_model']} ({trials[t]['numerics']})" for pair in ran for t in pair})
    dates = sorted({trials[t]["date"] for pair in ran for t in pair})
    lines += ["", f"Development start states (200 per seed); {', '.join(cpus)}; {dates[0]} to {dates[-1]}."]
    return "\n".join(lines)


BLOCKS: dict[str, Callable[[Path], str]] = {
    "load_test": load_test,
    "table1": table1, "headline": headline, "cross_cpu": cross_cpu, "run_time": run_time,
    "run_time_line": run_time_line, "benchmarks": benchmarks, "experiments": experiments, "twin": twin,
    "translator_diagnostics": translator_diagnostics, "ablations": ablations, "ablation_caption": ablation_caption,
    "bc_seed_spread": bc_seed_spread, "issue37": issue37, "probe_halves": probe_halves, "search": search,
    "confirm": confirm}
"""Block name -> its renderer."""

_BLOCK = re.compile(r"(<!-- generated:(\w+) -->\n)(.*?)(<!-- /generated:\2 -->)", re.S)


def render_page(text: str, root: Path = ROOT) -> str:
    """The page with every generated block rendered anew."""
    def sub(m: re.Match) -> str:
        name = m.group(2)
        if name not in BLOCKS:
            raise InputError(f"unknown generated block {name!r}; known: {sorted(BLOCKS)}")
        try:
            block = BLOCKS[name](root)
        except (KeyError, ValueError, IndexError) as err:
            # a report of another version, or a value edited by hand: a column missing, text where a number belongs
            raise InputError(f"generated block {name!r}: its reports do not hold what it reads ({type(err).__name__}: "
                             f"{err}); expected {EXPECTED}") from err
        return f"{m.group(1)}{block}\n{m.group(4)}"

    return _BLOCK.sub(sub, text)


def stale(root: Path = ROOT) -> list[str]:
    """``page: block`` for every generated block that differs from its reports."""
    out = []
    for page in PAGES:
        path = root / page
        if not path.exists():
            continue
        text = path.read_text()
        new = render_page(text, root)
        if new != text:
            old_blocks = {m.group(2): m.group(3) for m in _BLOCK.finditer(text)}
            new_blocks = {m.group(2): m.group(3) for m in _BLOCK.finditer(new)}
            out += [f"{page}: {k}" for k in new_blocks if new_blocks[k] != old_blocks.get(k)]
    return out


def main(argv: list[str] | None = None, root: Path = ROOT) -> int:
    """``python -m lfdt.docs [--check]``: rewrite the pages' generated blocks (or name the stale ones, exit 1). A
    report that is missing, cut short or not what a block reads is one line naming it, exit 2, and no page is
    written: every page is rendered before the first is replaced."""
    ap = inputs.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="exit 1 if a page disagrees with its reports; write nothing")
    args = ap.parse_args(argv)

    def run() -> int:
        if args.check:
            bad = stale(root)
            if bad:
                print("stale generated blocks (run `make docs`): " + ", ".join(bad), file=sys.stderr)
                return 1
            return 0
        pages = {page: (root / page).read_text() for page in PAGES if (root / page).exists()}
        new = {page: render_page(text, root) for page, text in pages.items()}
        for page, text in new.items():
            if text != pages[page]:
                (root / page).write_text(text)
                print(f"updated {page}")
        return 0

    return inputs.one_line_errors(run, "no page was written unless it says 'updated'")


if __name__ == "__main__":
    sys.exit(main())
