"""What every per-configuration job of the matrix stages shares: the configuration, its directories, F and F^-1.

A matrix stage (``stages/train_translator.py``, ``track_demos``, ``train_bc``, ``evaluate``) covers one method
and one demonstration count; its seeds are independent jobs that :func:`lfdt.parallel.run_jobs` runs side by
side. Each job opens its own MLflow run, writes its own files under ``<root>/<method>-d<demos>/s<seed>/`` and
returns its metrics; the stage gathers them into one report per (method, demos). The roots are dvc.yaml's paths: the
stage gets them on its command line and hands them to its jobs in their :class:`Config`. Each kind of job lives in its
own module of this package, importing only what it needs, so that a change to one stage's code reruns only
that stage.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from lfdt import methods, stage
from lfdt.config import Params
from lfdt.tasks.box_push import columns as box_columns

DYNAMICS_FILE = "dynamics.pt"
"""F and F^-1 in the dynamics folder (``stages/fit_dynamics.py`` writes it)."""

LAYOUT = box_columns.BOX_PUSH
"""The layout of the task the matrix stages serve: the simulated box push of Table I."""

DATA_FILE = {"raw": None, "translated": "translated.parquet", "executed": "executed.parquet"}
"""The BC training file each kind of method (:attr:`lfdt.methods.Method.data`) writes and reads."""


@dataclass(frozen=True)
class Config:
    """One configuration of a matrix stage, with the folders its job reads and writes (a stage sets those its jobs
    use, from its command line)."""

    method: str
    demos: int
    seed: int
    params: Params
    """params.yaml as the stage validated it (a worker does not read the file again)."""
    demos_dir: Path | None = None
    """The demonstrations of each pairing, ``<pairing>.parquet``."""
    random_dir: Path | None = None
    """The random motion of each domain, ``<domain>.parquet``."""
    dynamics_dir: Path | None = None
    """F and F^-1 (:data:`DYNAMICS_FILE`)."""
    translators_dir: Path | None = None
    """The translators, one folder per configuration."""
    bc_data_dir: Path | None = None
    """The BC training sets, one folder per configuration."""
    policies_dir: Path | None = None
    """The BC policies, one folder per configuration."""
    videos_dir: Path | None = None
    """The evaluation videos, one folder per configuration."""
    checkpoints_dir: Path | None = None
    """Resumable translator training, one folder per group of seeds (removed once its translators are saved)."""

    @property
    def group(self) -> str:
        """The (method, demos) a matrix stage instance covers, as in file names: ``lfdt-d50``."""
        return f"{self.method}-d{self.demos}"

    @property
    def name(self) -> str:
        """This configuration in run names: ``lfdt-d50-s0``."""
        return stage.config_name(self.method, self.demos, self.seed)

    def dir(self, root: Path) -> Path:
        """Its own directory under ``root``: ``<root>/<method>-d<demos>/s<seed>``."""
        return Path(root) / self.group / f"s{self.seed}"

    def tags(self) -> dict:
        return {"method": self.method, "demos": self.demos, "seed": self.seed, "config": self.name}


def configs(method: str, demos: int, seeds: list[int], params: Params, **dirs: Path) -> list[Config]:
    """The configurations of one matrix stage instance, one per seed; ``dirs`` are :class:`Config`'s folders its
    jobs use."""
    methods.get(method)
    return [Config(method, demos, s, params, **dirs) for s in seeds]


def groups(cfgs: list[Config], workers: int) -> list[list[Config]]:
    """The configurations split into at most ``workers`` groups of consecutive seeds, as even as can be: a group is
    one job, whose seeds train as one stacked model (a seed's result does not depend on its group)."""
    n = max(1, min(workers, len(cfgs)))
    size, extra = divmod(len(cfgs), n)
    out, start = [], 0
    for i in range(n):
        end = start + size + (1 if i < extra else 0)
        out.append(cfgs[start:end])
        start = end
    return [g for g in out if g]


def flatten(results: list[list[dict]]) -> list[dict]:
    """Per-seed results from per-group results, in seed order."""
    return [r for group in results for r in group]


IDENTIFIERS = frozenset({"demos", "seed"})
"""Keys of a metrics dict that say which configuration it is: params and tags of the run, never metrics."""


def numeric(d: dict) -> dict:
    """The int and float entries of a metrics dict (what MLflow takes as metrics), identifiers left out."""
    return {k: v for k, v in stage.numeric(d).items() if k not in IDENTIFIERS}
