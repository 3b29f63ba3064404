"""Where `make test`'s time goes: the test suite run as `make test` runs it (``pytest -n 2 --dist loadgroup``), each
test's phases (setup, call, teardown) timed on the pytest worker that ran them, and the whole machine's busy share
read from /proc/stat every 2 s meanwhile (it counts what the tests start outside pytest's own processes too: DVC,
stages, Ray's chains, servers). Then a summary: per worker its busy seconds and longest phases, the machine's mean
busy share, and the JSON of both (``--out``).

    python tools/suite_timeline.py                                   # make test's pytest run
    python tools/suite_timeline.py --workers 3 --out /tmp/n3.json    # another worker count
    python tools/suite_timeline.py --out /tmp/a.json -- tests/test_optim.py -k stack   # pytest arguments after --
    python tools/suite_timeline.py --summarise /tmp/a.jsonl          # an earlier run's raw timeline again

The set-up `make test` does first (tools/test_prereqs.sh) is not repeated: run `make test` once before. This file is
also the pytest plugin (``-p suite_timeline`` with tools/ on PYTHONPATH): with $LFDT_TIMELINE set, it appends one
JSON line per test phase to that file.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from collections import defaultdict
from datetime import date
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TIMELINE_ENV = "LFDT_TIMELINE"
"""The file the plugin appends its phases to (one JSON object per line); unset, the plugin records nothing."""
SAMPLE_S = 2.0
"""Seconds between two reads of /proc/stat."""
LONG_S = 15.0
"""A phase at least this long is listed by name in the summary."""


def _record(phase: str):
    @pytest.hookimpl(hookwrapper=True)
    def hook(item, *args, **kwargs):
        t0 = time.time()
        yield
        path = os.environ.get(TIMELINE_ENV)
        if path:
            rec = {"worker": os.environ.get("PYTEST_XDIST_WORKER", "main"), "test": item.nodeid, "phase": phase,
                   "t0": t0, "t1": time.time()}
            with open(path, "a") as fh:  # one short append per phase: the workers' lines do not interleave
                fh.write(json.dumps(rec) + "\n")
    return hook


pytest_runtest_setup = _record("setup")
pytest_runtest_call = _record("call")
pytest_runtest_teardown = _record("teardown")


def _cpu_times() -> tuple[int, int]:
    """(busy, total) jiffies of the whole machine since boot."""
    fields = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
    idle = fields[3] + fields[4]  # idle and iowait
    return sum(fields) - idle, sum(fields)


def _sample(out: list[tuple[float, float]], stop: threading.Event) -> None:
    busy0, total0 = _cpu_times()
    while True:
        stopped = stop.wait(SAMPLE_S)
        busy, total = _cpu_times()
        if total > total0:
            out.append((time.time(), (busy - busy0) / (total - total0)))
        busy0, total0 = busy, total
        if stopped:  # the last, shorter interval too: a suite that ends between two samples still has its own
            return


def _cpu_model() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown"


def summarise(phases: list[dict], busy: list[tuple[float, float]] | None = None) -> dict:
    """The timeline's summary: per worker its span, busy seconds and phases of at least :data:`LONG_S`; with
    ``busy`` (time, busy share) samples, the machine's mean busy share over the run."""
    if not phases:
        raise SystemExit("error: the timeline holds no test phase (did pytest run any test?)")
    start = min(p["t0"] for p in phases)
    per: dict[str, list[dict]] = defaultdict(list)
    for p in phases:
        per[p["worker"]].append(p)
    workers = {}
    for name, ps in sorted(per.items()):
        ps.sort(key=lambda p: p["t0"])
        workers[name] = {
            "first_s": round(ps[0]["t0"] - start, 1), "last_s": round(max(p["t1"] for p in ps) - start, 1),
            "busy_s": round(sum(p["t1"] - p["t0"] for p in ps), 1), "phases": len(ps),
            "long": [{"start_s": round(p["t0"] - start, 1), "s": round(p["t1"] - p["t0"], 1), "phase": p["phase"],
                      "test": p["test"]} for p in ps if p["t1"] - p["t0"] >= LONG_S]}
    end = max(p["t1"] for p in phases)
    summary = {"wall_s": round(end - start, 1), "workers": workers}
    inside = [b for t, b in busy or [] if start <= t <= end + SAMPLE_S]
    if inside:
        summary["machine_busy_share"] = round(sum(inside) / len(inside), 3)
        summary["machine_busy_samples"] = len(inside)
    return summary


def _print(summary: dict) -> None:
    print(f"tests ran {summary['wall_s']:.0f} s" + (
        f"; the machine was {100 * summary['machine_busy_share']:.0f} % busy (mean of "
        f"{summary['machine_busy_samples']} samples of {SAMPLE_S:g} s)" if "machine_busy_share" in summary else ""))
    for name, w in summary["workers"].items():
        print(f"{name}: {w['first_s']:.0f}-{w['last_s']:.0f} s, busy {w['busy_s']:.0f} s, {w['phases']} phases")
        for p in w["long"]:
            print(f"  {p['start_s']:7.0f} s {p['s']:6.0f} s  {p['phase']:8s} {p['test'][:110]}")


def main(argv: list[str] | None = None) -> int:
    """Run the suite with the timeline (or summarise a saved one); returns pytest's exit code."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workers", type=int, default=2, help="pytest-xdist workers (make test: 2); 0: no xdist")
    ap.add_argument("--out", type=Path, help="where the summary's JSON goes (the raw timeline beside it, .jsonl)")
    ap.add_argument("--summarise", type=Path, metavar="JSONL", help="summarise this raw timeline; run nothing")
    ap.add_argument("pytest_args", nargs="*", help="after --: pytest's arguments (default: the whole suite)")
    args = ap.parse_args(argv)
    if args.workers < 0:
        ap.error(f"--workers {args.workers}: expected 0 or more")
    if args.summarise is not None:
        try:
            phases = [json.loads(line) for line in args.summarise.read_text().splitlines() if line.strip()]
        except (OSError, json.JSONDecodeError) as e:
            raise SystemExit(f"error: {args.summarise}: not a timeline this tool wrote ({e})") from None
        _print(summarise(phases))
        return 0
    out = args.out or Path(f"/tmp/suite_timeline_{os.getpid()}.json")
    raw = out.with_suffix(".jsonl")
    raw.write_text("")  # a rerun does not append to an earlier run's timeline
    xdist = ["-n", str(args.workers), "--dist", "loadgroup"] if args.workers else []
    cmd = [sys.executable, "-m", "pytest", "-q", *xdist, "-p", "suite_timeline", *args.pytest_args]
    # an xdist worker's own variables stay out: run from a test, the suite's workers would take its name
    env = {**{k: v for k, v in os.environ.items() if not k.startswith("PYTEST_XDIST_")}, TIMELINE_ENV: str(raw),
           "MUJOCO_GL": "egl",
           "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}",
           "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT / "tools"), os.environ.get("PYTHONPATH")) if p)}
    busy: list[tuple[float, float]] = []
    stop = threading.Event()
    sampler = threading.Thread(target=_sample, args=(busy, stop), daemon=True)
    sampler.start()
    t0 = time.time()
    try:
        rc = subprocess.run(cmd, cwd=ROOT, env=env).returncode
    finally:
        stop.set()
        sampler.join()
    phases = [json.loads(line) for line in raw.read_text().splitlines() if line.strip()]
    summary = {"cpu_model": _cpu_model(), "cores": os.cpu_count(), "date": date.today().isoformat(),
               "pytest_workers": args.workers, "pytest_args": args.pytest_args, "pytest_exit_code": rc,
               "pytest_wall_s": round(time.time() - t0, 1), **summarise(phases, busy)}
    out.write_text(json.dumps(summary, indent=1) + "\n")
    _print(summary)
    print(f"summary: {out}; raw timeline: {raw}")
    return rc


if __name__ == "__main__":
    sys.exit(main())
