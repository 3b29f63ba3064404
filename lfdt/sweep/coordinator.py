"""The coordinator of a sweep: builds the shared stages once, fans the chains out as Ray tasks, then restores every
chain from the run cache and builds the reports with one ordinary `dvc repro`.

Progress survives a crash: each finished chain is written to a state file under ``.dvc/tmp/sweep/`` (keyed by the
commit, the params and the remote) the moment it reports, so rerunning the same command runs only the chains that
failed or never finished.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

import yaml
from tqdm import tqdm

from lfdt import inputs, mlflow_runs, reach
from lfdt.config import load_params
from lfdt.errors import StageError
from lfdt.files import temp_path
from lfdt.sweep import runcache
from lfdt.sweep.chain import RAN, ChainResult, ChainSpec, Remote, run_chain, safe_name, stage_env
from lfdt.sweep.plan import Plan, make_plan
from lfdt.sweep.points import TABLE, Point, compare, expand

OUTPUT_PATHS = ("params.yaml", "dvc.lock", "reports/")
"""Tracked files a sweep may find changed in the coordinator's workspace, with DVC's .gitignore files (params are
shipped to every chain; the rest are what the pipeline itself rewrites); any other change would not reach the
clones, so it stops the sweep."""
FORWARDED_ENV = ("MLFLOW_TRACKING_URI", "LFDT_MLFLOW_EXPERIMENT", "MLFLOW_TRACKING_TOKEN")
"""Set for every chain's stages as the coordinator has them. Remote credentials are not sent through Ray: each
node reads its own (``AWS_*`` in the environment of ``ray start``, or ``~/.aws``)."""


class SweepError(StageError):
    """The sweep cannot start or did not finish; the message names the chain, file or variable."""


def _git(root: Path, *args: str) -> str:
    proc = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SweepError(f"`git {' '.join(args)}` in {root} failed: {proc.stderr.strip()}")
    return proc.stdout.strip()


def check_project(root: Path) -> None:
    """``root`` is the project's folder (dvc.yaml, .dvc/) and its params.yaml passes the stages' own checks
    (:func:`lfdt.config.load_params`: a ParamsError naming the file or key otherwise)."""
    if not (root / "dvc.yaml").is_file() or not (root / ".dvc").is_dir():
        raise SweepError(f"{root} is not the project's folder (it has no dvc.yaml and .dvc/): run python -m "
                         "lfdt.sweep where dvc.yaml is")
    load_params(root / "params.yaml")


def check_workspace(root: Path) -> str:
    """The commit the chains clone (:func:`check_project` first); SweepError when the workspace has changes they
    would not see."""
    check_project(root)
    commit = _git(root, "rev-parse", "HEAD")
    changed = _git(root, "diff", "--name-only", "HEAD").splitlines()  # staged or not, relative to the root
    stray = [p for p in changed if not p.startswith(OUTPUT_PATHS) and Path(p).name != ".gitignore"]
    if stray:
        raise SweepError(f"uncommitted changes in {', '.join(stray[:5])}: the chains clone commit {commit[:7]} and "
                         f"would not see them; commit them first (params.yaml may differ: it is sent to every chain)")
    return commit


def tracking_env(forward: list[str]) -> dict[str, str]:
    """The variables every chain gets; SweepError when no shared tracking store is set."""
    uri = os.environ.get("MLFLOW_TRACKING_URI", "")
    if not uri or uri.startswith(("sqlite:", "file:")) or "://" not in uri:
        raise SweepError(f"MLFLOW_TRACKING_URI={uri!r}: a sweep's chains run on other machines, so their runs need "
                         f"a tracking server every node reaches (e.g. http://head-node:5000; README, 'When one "
                         f"machine is not enough')")
    missing = [v for v in forward if v not in os.environ]
    if missing:
        raise SweepError(f"--forward-env names variables that are not set here: {', '.join(missing)}")
    return {k: os.environ[k] for k in (*FORWARDED_ENV, *forward) if k in os.environ}


class SweepState:
    """Finished chains of one sweep (commit, params, remote), kept in a JSON file written after each chain."""

    def __init__(self, state_dir: Path, commit: str, params_yaml: str, remote: Remote):
        # the params' values, not their text: a point of --set writes the same params in another layout
        params = yaml.safe_load(params_yaml)
        key = hashlib.sha256(json.dumps([commit, params, asdict(remote)], sort_keys=True).encode()).hexdigest()[:16]
        self.path = state_dir / f"{key}.json"
        self.finished: dict[str, dict] = {}
        if self.path.exists():
            self.finished = json.loads(self.path.read_text()).get("finished", {})

    def done(self, result: ChainResult) -> None:
        self.finished[result.name] = {"host": result.host, "wall_s": round(result.wall_s, 1), "ran": result.ran}
        tmp = temp_path(self.path)
        tmp.write_text(json.dumps({"finished": self.finished}, indent=2) + "\n")
        os.replace(tmp, self.path)


def _dvc_streamed(root: Path, env: dict[str, str], *args: str) -> str:
    """Run dvc with its output shown as it comes and returned."""
    proc = subprocess.Popen([sys.executable, "-m", "dvc", *args], cwd=root, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    out = []
    for line in proc.stdout:
        sys.stdout.write(line)
        out.append(line)
    if proc.wait() != 0:
        raise SweepError(f"`dvc {' '.join(args)}` in {root} exited with {proc.returncode}")
    return "".join(out)


def run_sweep(root: Path, remote: Remote, address: str | None = None, cpus_per_chain: float = 1.0,
              repo_url: str | None = None, forward_env: list[str] | None = None, workdir: str | None = None,
              only: list[str] | None = None, state_dir: Path | None = None, final: bool = True) -> dict:
    """The whole sweep; returns a summary (chains run, skipped and failed, what the final `dvc repro` ran).

    ``state_dir`` holds the record of finished chains and the logs of failed ones (default ``root``'s
    ``.dvc/tmp/sweep``; the points of ``--set`` keep theirs in the workspace's, so a point with the params of an
    earlier sweep there reruns no chain). Without ``final`` the sweep ends when the chains' run records are in
    ``root``'s cache, before the last `dvc repro`: a point's experiment restores the chains and builds the rest.

    SweepError when a chain failed (named, with the end of its log; the rest are kept) or when the final
    `dvc repro` had to run a chain's stage itself.
    """
    import ray

    start = time.monotonic()
    root = root.resolve()
    check_services(address, remote)
    commit = check_workspace(root)
    extra = tracking_env(forward_env or [])
    # the experiment and its tags exist before any stage starts: stages of two chains that both find them missing
    # on a fresh server race to create them, and the server's database refuses the second (seen on PostgreSQL)
    mlflow_runs.experiment_id()
    env = stage_env(root, extra)
    remote.configure(root)
    params_yaml = (root / "params.yaml").read_text()
    plan = make_plan(root)
    unknown = sorted(set(only or []) - set(plan.chains))
    if unknown:
        raise SweepError(f"--chains names no chain of this plan: {', '.join(unknown)} (see --list)")

    print(f"sweep of commit {commit[:7]}: {len(plan.shared)} shared stages, {len(plan.chains)} chains, "
          f"{len(plan.final)} final stages", flush=True)
    runcache.fetch(root, remote.name)
    _dvc_streamed(root, env, "repro", "--pull", *plan.shared)
    runcache.publish(root, remote.name)

    state_dir = state_dir or root / ".dvc" / "tmp" / "sweep"
    state = SweepState(state_dir, commit, params_yaml, remote)
    todo = [c for c in plan.chains if c not in state.finished and (not only or c in only)]
    skipped = [c for c in plan.chains if c in state.finished]
    if skipped:
        print(f"{len(skipped)} chains finished in an earlier run of this sweep, not run again: {', '.join(skipped)}")
    failed: list[ChainResult] = []
    if todo:
        ray.init(address=address, log_to_driver=False, configure_logging=False)
        try:
            task = ray.remote(run_chain).options(num_cpus=cpus_per_chain, max_retries=0)
            pending = {task.remote(ChainSpec(name=c, stages=plan.chains[c], shared=plan.shared,
                                             repo_url=repo_url or str(root), commit=commit, params_yaml=params_yaml,
                                             remote=remote, env=extra, workdir=workdir)): c for c in todo}
            with tqdm(total=len(todo), desc="chains", unit="chain") as bar:
                while pending:
                    ready, _ = ray.wait(list(pending), num_returns=1)
                    name = pending.pop(ready[0])
                    try:
                        result = ray.get(ready[0])
                    except Exception as e:  # noqa: BLE001 - a lost worker or node: reported as this chain's failure
                        result = ChainResult(name, ok=False, host="?", wall_s=0.0, ran=[], restored=[],
                                             error=f"{type(e).__name__}: {e}")
                    if result.ok:
                        state.done(result)
                    else:
                        failed.append(result)
                    bar.write(f"{'done' if result.ok else 'FAILED'}: {name} on {result.host} "
                              f"({result.wall_s:.0f} s; ran {len(result.ran)}, restored {len(result.restored)})")
                    bar.update()
        finally:
            ray.shutdown()
    if failed:
        logs = state_dir / "failed"
        logs.mkdir(parents=True, exist_ok=True)
        for r in failed:
            kept = f"clone kept on {r.host}: {r.clone}\n" if r.clone else ""
            (logs / f"{safe_name(r.name)}.log").write_text(f"{r.error}\n{kept}{r.log_tail}")
        names = ", ".join(f"{r.name} ({r.error})" for r in failed)
        raise SweepError(f"{len(failed)} of {len(plan.chains)} chains failed: {names}. Their logs are in {logs}; "
                         f"rerun the same command to run only them (finished chains are kept)")
    def summary(final_ran: list[str]) -> dict:
        return {"commit": commit, "chains_run": todo, "chains_skipped": skipped, "final_ran": final_ran,
                "final": plan.final, "wall_s": time.monotonic() - start}

    if only:
        return summary([])
    runcache.fetch(root, remote.name)
    if not final:
        return summary([])
    chain_stages = [s for stages in plan.chains.values() for s in stages]
    out = _dvc_streamed(root, env, "repro", "--pull")
    ran = RAN.findall(out)
    rerun = sorted(set(ran) & set(chain_stages))
    if rerun:
        raise SweepError(f"the final `dvc repro` ran {len(rerun)} chain stages itself ({', '.join(rerun[:5])}): "
                         f"their run records or objects are missing from the remote {remote.name!r}")
    return summary(ran)


def _point_clone(root: Path, commit: str, point: Point) -> Path:
    """The workspace in which ``point`` is swept: a clone of ``root`` at ``commit`` with the point's params.yaml and
    ``root``'s DVC cache (so every output and run record lands where the experiment is recorded). Reused when it
    exists: its sweep state makes a rerun skip the chains that finished."""
    clone = root / ".dvc" / "tmp" / "sweep" / "points" / f"{commit[:7]}-{point.key}"
    if not (clone / ".git").exists():
        clone.parent.mkdir(parents=True, exist_ok=True)
        tmp = clone.with_name(clone.name + ".partial")  # a crash mid-clone leaves this, never a half clone
        shutil.rmtree(tmp, ignore_errors=True)
        _git(clone.parent, "clone", "--quiet", "--no-checkout", "--", str(root), tmp.name)
        _git(tmp, "checkout", "--quiet", commit)
        os.replace(tmp, clone)
    (clone / "params.yaml").write_text(point.params_yaml)
    from dvc.config import ConfigError
    from dvc.repo import Repo

    try:  # in-process, as Remote.configure: a `dvc config` command per key costs seconds of imports
        with contextlib.chdir(clone), Repo(str(clone)) as repo, repo.config.edit("local") as conf:
            conf["cache"]["dir"] = str(root / ".dvc" / "cache")
            conf["cache"]["type"] = "reflink,hardlink,copy"
    except ConfigError as err:
        raise SweepError(f"could not point {clone}'s DVC cache at {root}'s: {err}") from None
    return clone


def _experiments(root: Path, env: dict[str, str]) -> set[str]:
    proc = subprocess.run([sys.executable, "-m", "dvc", "exp", "list", "--name-only"], cwd=root, env=env,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise SweepError(f"`dvc exp list` in {root} failed: {proc.stderr.strip() or proc.stdout.strip()}")
    return set(proc.stdout.split())


def _experiment_file(root: Path, commit: str, name: str, path: str) -> str:
    """``path`` as experiment ``name`` (of baseline ``commit``) holds it; '' when it has none."""
    ref = f"refs/exps/{commit[:2]}/{commit[2:]}/{name}"
    proc = subprocess.run(["git", "show", f"{ref}:{path}"], cwd=root, capture_output=True, text=True)
    return proc.stdout if proc.returncode == 0 else ""


RAY_LOCAL = (None, "", "auto", "local")
"""``--address`` values that start or find a Ray instance on this machine rather than name a cluster's head."""
RAY_HEAD_PORT = 6379
"""The port of a Ray head given as a bare host."""


def check_services(address: str | None, remote: Remote, timeout: float = reach.TIMEOUT_S) -> None:
    """Before any work: the Ray cluster's head, the tracking server or database (``MLFLOW_TRACKING_URI``) and the
    remote's S3 endpoint each accept a connection within ``timeout`` seconds, or :class:`lfdt.reach.Unreachable`
    names the one that does not and its address (Ray, MLflow and boto would otherwise retry for minutes, Ray only
    after the shared stages have run). The Ray address must answer as gRPC does, and the tracking store as
    :func:`lfdt.mlflow_runs.check_tracking_uri` wants (a server not answering 5xx); ``LFDT_MLFLOW_EXPERIMENT`` must
    be a name the store can keep (:class:`lfdt.errors.InputError` otherwise)."""
    if address not in RAY_LOCAL:
        # Ray's head (GCS) and its client server both speak gRPC; with TLS on (RAY_USE_TLS) the plain-text
        # handshake cannot tell, so a connection is all that is checked
        tls = os.environ.get("RAY_USE_TLS", "0").strip().lower() in ("1", "true", "yes")
        inputs.tcp_service(address, "the Ray cluster (--address or RAY_ADDRESS)", "tcp" if tls else "grpc", timeout,
                           default_port=RAY_HEAD_PORT,
                           hint=f"the address of a Ray head (`ray start --head` prints it; port {RAY_HEAD_PORT}, or "
                                f"ray://host:10001 for Ray's client)")
    uri = mlflow_runs.tracking_uri()
    if uri.split(":", 1)[0].split("+")[0] in ("http", "https", "postgresql", "postgres", "mysql", "mssql"):
        reach.check(uri, "the MLflow tracking store (MLFLOW_TRACKING_URI)", timeout=timeout)
    mlflow_runs.check_tracking_uri(uri, timeout)  # answers, and not with 5xx (it accepting a connection is not all)
    mlflow_runs.experiment_name()  # forwarded to every chain's stages: one the store can keep
    if remote.endpoint_url:
        reach.check(remote.endpoint_url, f"the S3 endpoint of DVC remote {remote.name!r} (--endpoint-url)",
                    timeout=timeout)


def run_points(root: Path, sets: list[str], remote: Remote, **kwargs) -> dict:
    """Sweep every point of ``--set`` (:mod:`lfdt.sweep.points`) and record each in ``root`` as a DVC experiment
    named after its params; returns a summary. ``kwargs`` go to :func:`run_sweep` (the chains of all points run on
    the same cluster, one point after another).

    A point whose chains failed is reported by name and the others go on; rerunning the same command skips the
    points already recorded and, in a point that failed, the chains that finished. SweepError at the end when any
    point failed, or when recording one had to run a stage (every stage must come from the run cache).
    """
    start = time.monotonic()
    root = root.resolve()
    check_services(kwargs.get("address"), remote)
    commit = check_workspace(root)
    env = stage_env(root, tracking_env(kwargs.get("forward_env") or []))
    points = expand((root / "params.yaml").read_text(), sets)
    remote.configure(root)
    recorded = _experiments(root, env)
    done = [p.name for p in points if p.name in recorded]
    if done:
        print(f"{len(done)} of {len(points)} points are experiments already, not run again: {', '.join(done)}")
    failed: dict[str, str] = {}
    ran_points = []
    for i, point in enumerate(points, 1):
        if point.name in recorded:
            continue
        print(f"point {i}/{len(points)} ({point.name}): {point.describe()}", flush=True)
        clone = _point_clone(root, commit, point)
        try:
            summary = run_sweep(clone, remote, state_dir=root / ".dvc" / "tmp" / "sweep", final=False, **kwargs)
        except SweepError as err:
            print(f"point {point.name} FAILED: {err}", flush=True)
            failed[point.name] = str(err)
            continue
        # the experiment: shared and chain stages restored from the run records the point's sweep fetched (their
        # objects pulled from the remote where the cache lacks them), the final stages (reports) built
        try:
            out = _dvc_streamed(root, env, "exp", "run", "--temp", "--pull", "-n", point.name, *point.set_args())
        except SweepError as err:
            print(f"point {point.name} FAILED: {err}", flush=True)
            failed[point.name] = str(err)
            continue
        ran = sorted(set(RAN.findall(out)) - set(summary["final"]))
        if ran:
            failed[point.name] = (f"recording it as an experiment ran {len(ran)} stages ({', '.join(ran[:5])}) "
                                  f"instead of restoring them from the run cache: its params differ from the "
                                  f"swept ones")
            continue
        shutil.rmtree(clone, ignore_errors=True)
        ran_points.append(point.name)
    tables = {p.name: _experiment_file(root, commit, p.name, TABLE) for p in points if p.name not in failed}
    if any(tables.values()):
        print(f"\nTable I of each point ({TABLE} of its experiment; success rate [95 % interval], seeds):\n"
              + compare({k: v for k, v in tables.items() if v}), flush=True)
    if failed:
        raise SweepError(f"{len(failed)} of {len(points)} points failed: "
                         + "; ".join(f"{n}: {e}" for n, e in failed.items())
                         + ". Rerun the same command: recorded points and finished chains are kept")
    return {"commit": commit, "points_run": ran_points, "points_skipped": done, "wall_s": time.monotonic() - start}


def describe(plan: Plan) -> str:
    """The plan as text (``--list``)."""
    lines = [f"shared (built once, here): {', '.join(plan.shared)}"]
    lines += [f"chain {name}: {', '.join(stages)}" for name, stages in plan.chains.items()]
    lines.append(f"final (here, after the chains): {', '.join(plan.final)}")
    return "\n".join(lines)
