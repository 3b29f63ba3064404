"""Several param sets in one sweep: ``--set KEY=V1,V2`` (repeatable), like ``dvc exp run -S``'s grids.

Every combination of the values is a *point*: the workspace's params.yaml with those keys changed. The coordinator
sweeps each point in a clone of its own (whose DVC cache is the workspace's), then records it in the workspace as a
DVC experiment, so ``dvc exp show`` and ``dvc metrics diff`` compare the points and ``dvc exp apply`` brings one
back. Seeds are params like any other: ``--set grid.seeds=[3,4,5],[3,4,5,6,7,8]`` sweeps three and six seeds.
"""

from __future__ import annotations

import hashlib
import io
import itertools
import json
import re
from dataclasses import dataclass
from typing import Any

import yaml

from lfdt.config import ParamsError, validate_params
from lfdt.errors import StageError
from lfdt.tasks import registry


class PointError(StageError):
    """A ``--set`` argument is malformed, names no param, or gives an invalid value (the message says which)."""


@dataclass(frozen=True)
class Point:
    """One param set of a sweep."""

    overrides: tuple[tuple[str, Any], ...]
    """(dotted key, value) pairs, in the order the ``--set`` arguments gave the keys."""
    params_yaml: str
    """The full params.yaml of this point (the workspace's, comments kept, with the overrides applied)."""
    named_by: tuple[str, ...] = ()
    """The keys its name shows: those whose value differs between the points of its sweep (all when none does)."""

    @property
    def key(self) -> str:
        """A short hash of the params: the same point gets the same clone and experiment name."""
        return hashlib.sha256(self.params_yaml.encode()).hexdigest()[:6]

    @property
    def name(self) -> str:
        """The DVC experiment name: the last part of each key that tells the points apart and its value, then the
        key (e.g. ``lambda_dyn-0.5-3fa2c1``)."""
        shown = self.named_by or tuple(k for k, _ in self.overrides)
        parts = [f"{k.rsplit('.', 1)[-1]}-{_compact(v)}" for k, v in self.overrides if k in shown]
        readable = re.sub(r"[^A-Za-z0-9_.-]+", "_", "-".join(parts)).strip("._-")[:60].rstrip("._-")
        return f"{readable}-{self.key}" if readable else f"point-{self.key}"

    def set_args(self) -> list[str]:
        """The overrides as ``dvc exp run`` arguments (``-S key=value``, values in JSON, which DVC's parser reads)."""
        return [a for k, v in self.overrides for a in ("-S", f"{k}={json.dumps(v)}")]

    def describe(self) -> str:
        """The overrides as ``key=value, ...``."""
        return ", ".join(f"{k}={json.dumps(v)}" for k, v in self.overrides) or "(the workspace's params)"


def _compact(v: Any) -> str:
    if isinstance(v, list):
        return ".".join(_compact(x) for x in v)
    return str(v)


def split_values(text: str) -> list[str]:
    """Split ``V1,V2,...`` at the commas outside brackets and quotes (``[3,4],[5]`` is two values)."""
    parts, depth, quote, cur = [], 0, "", []
    for ch in text:
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append("".join(cur))
            cur = []
            continue
        cur.append(ch)
    parts.append("".join(cur))
    return [p.strip() for p in parts]


def parse_sets(sets: list[str]) -> list[tuple[str, list[Any]]]:
    """``KEY=V1,V2`` arguments as (key, values); PointError naming the argument when one is malformed."""
    out: list[tuple[str, list[Any]]] = []
    for arg in sets:
        key, sep, values = arg.partition("=")
        key = key.strip()
        if not sep or not key or not values.strip():
            raise PointError(f"--set {arg!r}: expected KEY=VALUE[,VALUE...], e.g. translator.lambda_dyn=0.5,2")
        if key in dict(out):
            raise PointError(f"--set names {key!r} twice: give all its values in one argument (V1,V2)")
        parsed = []
        for v in split_values(values):
            if not v:
                raise PointError(f"--set {arg!r}: an empty value (two commas in a row, or one at the end)")
            try:
                parsed.append(yaml.safe_load(v))
            except yaml.YAMLError as err:
                raise PointError(f"--set {arg!r}: {v!r} is not a YAML value ({err.problem})") from None
        out.append((key, parsed))
    return out


def apply(params_yaml: str, overrides: tuple[tuple[str, Any], ...]) -> str:
    """``params_yaml`` with each dotted key set to its value, comments kept; PointError when a key is not in the
    file or the result fails the params schema."""
    from ruamel.yaml import YAML
    from ruamel.yaml.comments import CommentedSeq

    rt = YAML()
    rt.width = 4096
    doc = rt.load(params_yaml)
    for key, value in overrides:
        node, parts = doc, key.split(".")
        for i, part in enumerate(parts):
            if not isinstance(node, dict) or part not in node:
                raise PointError(f"--set {key}: params.yaml has no {'.'.join(parts[:i + 1])!r}")
            if i < len(parts) - 1:
                node = node[part]
        if isinstance(value, list):  # flow style, as params.yaml writes its lists
            value = CommentedSeq(value)
            value.fa.set_flow_style()
        node[parts[-1]] = value
    buf = io.StringIO()
    rt.dump(doc, buf)
    text = buf.getvalue()
    try:
        params = validate_params(yaml.safe_load(text))
        registry.check_twin_names(params.twin)  # preflight's check that holds on every machine of a cluster
    except (ParamsError, StageError) as err:
        raise PointError(f"--set {', '.join(k for k, _ in overrides)}: {err}") from None
    return text


def expand(params_yaml: str, sets: list[str]) -> list[Point]:
    """Every combination of the ``--set`` values, each a point (in the order of the arguments, last key fastest)."""
    parsed = parse_sets(sets)
    keys = [k for k, _ in parsed]
    varying = tuple(k for k, values in parsed if len(values) > 1)
    points = []
    for combo in itertools.product(*(values for _, values in parsed)):
        overrides = tuple(zip(keys, combo, strict=True))
        points.append(Point(overrides, apply(params_yaml, overrides), varying))
    if len({p.params_yaml for p in points}) < len(points):
        raise PointError("--set gives the same value twice for a key: each point must differ")
    return points


TABLE = "reports/table1.csv"
"""What :func:`compare` reads from each point's experiment."""


def compare(tables: dict[str, str]) -> str:
    """Table I of several points side by side (Markdown): per method and demo count, each point's success rate with
    its 95 % interval and number of seeds ('-' where a point has no such row). ``tables``: point name -> the text of
    its ``reports/table1.csv``."""
    import pandas as pd

    if not tables:
        return ""
    cols = []
    for name, text in tables.items():
        df = pd.read_csv(io.StringIO(text))
        cell = [f"{r.success_rate:.1%} [{r.ci95_low:.0%}, {r.ci95_high:.0%}], {r.seeds} seeds"
                for r in df.itertuples()]
        cols.append(pd.Series(cell, index=pd.MultiIndex.from_frame(df[["method", "demos"]]), name=name))
    table = pd.concat(cols, axis=1, sort=False).fillna("-")
    lines = ["| method | demos | " + " | ".join(table.columns) + " |", "|---|---|" + "---|" * len(table.columns)]
    lines += [f"| {m} | {d} | " + " | ".join(row) + " |" for (m, d), row in zip(table.index, table.values,
                                                                                  strict=True)]
    return "\n".join(lines)
