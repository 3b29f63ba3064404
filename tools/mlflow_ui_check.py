"""Open the MLflow UI in headless Chromium and check that it answers: the experiment opens on its runs table, and
each view of :mod:`lfdt.mlflow_views` shows its columns and runs. Screenshots go to ``docs/mlflow-ui/``.

    make ui-check          # the workspace's store (mlflow.db), after `dvc repro`
    python tools/mlflow_ui_check.py --store sqlite:////path/to/mlflow.db --out /tmp/shots

Needs Debian's ``chromium`` (``apt-get install chromium``); exits 1 naming what the UI did not show, 2 when Chromium
or the store is missing.
"""

from __future__ import annotations

import lfdt.numerics  # noqa: F401  (first: pins the numeric code paths before numpy, torch or mujoco load)

import argparse
import html
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lfdt import mlflow_runs, mlflow_views  # noqa: E402

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--window-size=1920,1000", "--virtual-time-budget=20000"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _chromium(chromium: str, url: str, *args: str) -> str:
    with tempfile.TemporaryDirectory() as profile:
        out = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *args, url],
                             capture_output=True, text=True, timeout=180)
    if out.returncode != 0:
        raise SystemExit(f"error: chromium failed on {url}: {out.stderr[-1000:]}")
    return out.stdout


def _text(chromium: str, url: str) -> str:
    """The rendered page's visible text (tags stripped)."""
    return html.unescape(re.sub(r"<[^>]+>", " ", _chromium(chromium, url, "--dump-dom")))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--store", default=None, help="tracking store URI (default: the workspace's mlflow.db)")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "mlflow-ui", help="folder for the screenshots")
    args = ap.parse_args()
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        print("error: no chromium on PATH (Debian: apt-get install chromium)", file=sys.stderr)
        return 2
    store = args.store or mlflow_runs.tracking_uri()
    if store.startswith("sqlite:///") and not Path(store.removeprefix("sqlite:///")).exists():
        print(f"error: {store} does not exist: run `dvc repro` first", file=sys.stderr)
        return 2
    port = _free_port()
    ui = f"http://127.0.0.1:{port}"
    server = subprocess.Popen([str(Path(sys.executable).parent / "mlflow"), "server", "--backend-store-uri", store,
                               "--host", "127.0.0.1", "--port", str(port), "--workers", "1"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    problems = []
    try:
        deadline = time.time() + 120
        while True:
            try:
                urllib.request.urlopen(f"{ui}/health", timeout=5).read()
                break
            except OSError:
                if server.poll() is not None or time.time() > deadline:
                    print(f"error: mlflow server on {store} did not start", file=sys.stderr)
                    return 2
                time.sleep(0.5)
        os.environ["MLFLOW_TRACKING_URI"] = ui
        exp_id, urls = mlflow_views.install()
        import mlflow

        client = mlflow.MlflowClient(ui)
        args.out.mkdir(parents=True, exist_ok=True)
        # name: (URL fragment, what it shows, texts it must show)
        checks = {"experiment": (f"#/experiments/{exp_id}?{mlflow_views.ML_WORKFLOW}", "the experiment's runs table",
                                 ["Runs", "matching runs", "pipeline "])}
        for frag, (view, state) in urls.items():
            # the run the view lists first
            runs = client.search_runs([exp_id], state["searchFilter"], max_results=1, order_by=[view.search_order()])
            want = [k.split("`")[1] for k in view.columns] + [r.info.run_name for r in runs]
            if not runs:
                problems.append(f"{view.key}: no {view.stage} runs in {store}")
            checks[view.key] = (frag, view.title, want)
        for name, (frag, title, want) in checks.items():
            url = f"{ui}/{frag}"
            text = _text(chromium, url)
            missing = [w for w in want if w not in text]
            _chromium(chromium, url, f"--screenshot={args.out / (name + '.png')}")
            status = "ok" if not missing else f"MISSING {missing}"
            print(f"{name:18s} {status:10s} {title}")
            if missing:
                problems.append(f"{name}: {url} does not show {missing}")
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        try:
            server.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
    for p in problems:
        print(f"error: {p}", file=sys.stderr)
    print(f"screenshots in {args.out}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
