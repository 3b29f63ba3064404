"""Parquet datasets of transitions, in LeRobot's conventions.

One row per transition: ``episode_index``, ``frame_index``, ``timestamp`` (s since the episode
started), the state columns (``state.<name>``), the action columns (``action.<name>``), the next
state (``next_state.<name>``), and kind-specific extras. Column names come from the task's
:class:`lfdt.layout.TaskLayout`. Every field carries a ``description`` (and ``unit``) in its pyarrow metadata;
the schema metadata key ``lfdt`` holds a JSON document with the kind, the domain, the layout, the
environment parameters, the seed and whatever the writer adds.

Files are written atomically (a temporary file, then ``os.replace``): a crash never leaves a
half-written dataset under the final name.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from lfdt import layout
from lfdt.errors import StageError, first_line
from lfdt.files import write_atomic

META_KEY = b"lfdt"
INDEX_COLUMNS = ("episode_index", "frame_index", "timestamp")
UNNAMED_TASK = "box_push"
"""The task of a file whose metadata names none: the simulated box push's files were written before tasks had
names (its registry key, :data:`lfdt.tasks.registry.TASKS`)."""


def _unit(name: str) -> str:
    q = name.split(".")[-1]
    if q.startswith("dq"):
        return "rad/s"
    if q.startswith("q") or q in ("yaw", "pitch"):
        return "rad"
    if q.startswith("tau"):
        return "1 (normalised torque command in [-1, 1])"
    return "m"


def _describe(prefix: str, name: str) -> str:
    arm, qty = name.split(".", 1)
    who = layout.ARM_TITLES.get(arm, "object" if arm == "obj" else arm)
    what = {"state.": "state at frame t", "next_state.": "state at frame t+1",
            "action.": "robot action at frame t", "human_action.": "human stand-in's action at frame t "
            "(diagnostics only: translation and BC must not read it)"}[prefix]
    return f"{who} {qty}, {what}"


def transitions_schema(state_cols: list[str], action_cols: list[str], human_action_cols: list[str] = (),
                       extra: Mapping[str, tuple[pa.DataType, str]] | None = None,
                       metadata: Mapping[str, Any] | None = None) -> pa.Schema:
    """The pyarrow schema of a transitions table, with per-field descriptions and the lfdt metadata."""
    fields = [
        pa.field("episode_index", pa.int64(), metadata={"description": "episode number within this file, from 0"}),
        pa.field("frame_index", pa.int64(), metadata={"description": "control step within the episode, from 0"}),
        pa.field("timestamp", pa.float32(), metadata={"description": "time since the episode started", "unit": "s"}),
    ]
    for prefix, cols in ((layout.STATE_PREFIX, state_cols), (layout.ACTION_PREFIX, action_cols),
                         (layout.HUMAN_ACTION_PREFIX, human_action_cols), (layout.NEXT_STATE_PREFIX, state_cols)):
        fields += [pa.field(prefix + c, pa.float32(), metadata={"description": _describe(prefix, c), "unit": _unit(c)})
                   for c in cols]
    for name, (dtype, desc) in (extra or {}).items():
        fields.append(pa.field(name, dtype, metadata={"description": desc}))
    meta = {META_KEY: json.dumps(metadata or {}, default=str).encode()}
    return pa.schema(fields, metadata=meta)


def transitions_table(schema: pa.Schema, episode_index: np.ndarray, frame_index: np.ndarray, dt: float,
                      states: np.ndarray, actions: np.ndarray, next_states: np.ndarray,
                      human_actions: np.ndarray | None = None, extra: Mapping[str, np.ndarray] | None = None
                      ) -> pa.Table:
    """Assemble a table in ``schema``'s column order from arrays (rows = transitions)."""
    cols: dict[str, np.ndarray] = {
        "episode_index": np.asarray(episode_index, dtype=np.int64),
        "frame_index": np.asarray(frame_index, dtype=np.int64),
        "timestamp": (np.asarray(frame_index) * dt).astype(np.float32),
    }
    blocks = {layout.STATE_PREFIX: states, layout.ACTION_PREFIX: actions, layout.NEXT_STATE_PREFIX: next_states,
              layout.HUMAN_ACTION_PREFIX: human_actions}
    for prefix, arr in blocks.items():
        names = [f.name for f in schema if f.name.startswith(prefix)]
        if not names:
            continue
        arr = np.asarray(arr, dtype=np.float32)
        if arr.ndim != 2 or arr.shape[1] != len(names):
            raise ValueError(f"{prefix}* expects {len(names)} columns, got array of shape {arr.shape}")
        cols.update({n: arr[:, i] for i, n in enumerate(names)})
    cols.update(extra or {})
    missing = [f.name for f in schema if f.name not in cols]
    if missing:
        raise ValueError(f"no data for columns {missing}")
    return pa.Table.from_arrays([pa.array(cols[f.name], type=f.type) for f in schema], schema=schema)


def write_table(table: pa.Table, path: str | Path) -> Path:
    """Write a Parquet file atomically (an OSError, a full disk, is an OutputError naming ``path``)."""
    return write_atomic(path, lambda tmp: pq.write_table(table, tmp, compression="zstd"))


def _first_file(path: str | Path) -> Path:
    """A Parquet file itself, or the first file of a directory of Parquet files (a recording); the others are
    checked against it where the directory is read (:func:`read_transitions`, :func:`_directory_files`)."""
    path = Path(path)
    return _parquet_files(path)[0] if path.is_dir() else path


def _parquet_files(path: Path) -> list[Path]:
    """The Parquet files of a directory, in order (a FileNotFoundError when it holds none)."""
    files = sorted(path.glob("*.parquet"))
    if not files:
        raise FileNotFoundError(f"no Parquet files in {path}")
    return files


IDENTITY_KEYS = ("kind", "domain", "task")
"""Metadata every file of one directory of transitions (a recording) shares."""


def _directory_files(path: Path) -> list[Path]:
    """The Parquet files of a directory (a recording: one file per episode), in order; a DataFileError naming the
    file that is not a readable Parquet file, or whose columns or kind, domain or task differ from the first's:
    readers take the first file's schema and metadata for the whole directory, so a file copied in from another
    recording would otherwise be read with it."""
    files = _parquet_files(path)
    first = None
    for f in files:
        if not f.is_file():
            raise DataFileError(f"{f}: not a file ({'a folder' if f.is_dir() else 'a broken link'}); a directory "
                                f"of transitions holds one Parquet file per episode")
        with _readable(f):
            schema = pq.read_schema(f)
        meta = read_schema_metadata(schema)
        identity = {k: meta.get(k) for k in IDENTITY_KEYS}
        columns = [(c.name, str(c.type)) for c in schema]
        if first is None:
            first = (f, identity, columns)
            continue
        if identity != first[1]:
            raise DataFileError(f"{f} holds {_what(identity)}, but {first[0].name} beside it holds "
                                f"{_what(first[1])}: one directory holds one recording (move the file out)")
        if columns != first[2]:
            theirs, ours = dict(columns), dict(first[2])
            diff = ([f"missing {c}" for c in ours if c not in theirs] + [f"extra {c}" for c in theirs if c not in ours]
                    + [f"{c} is {theirs[c]}, not {ours[c]}" for c in ours if c in theirs and theirs[c] != ours[c]])
            raise DataFileError(f"{f}: its columns differ from {first[0].name}'s beside it ({'; '.join(diff[:3])}"
                                f"{'; ...' if len(diff) > 3 else ''}): one directory holds one recording")
    return files


def _what(identity: dict) -> str:
    return ", ".join(f"{k} {identity[k]!r}" for k in IDENTITY_KEYS)


def read_schema_metadata(schema: pa.Schema) -> dict:
    """The lfdt metadata document carried by a schema."""
    raw = (schema.metadata or {}).get(META_KEY)
    return json.loads(raw) if raw is not None else {}


def read_metadata(path: str | Path) -> dict:
    """The lfdt metadata document of a Parquet file (or of a recording directory's files)."""
    schema = pq.read_schema(_first_file(path))
    if META_KEY not in (schema.metadata or {}):
        raise ValueError(f"{path} has no lfdt metadata: not written by lfdt.data")
    return read_schema_metadata(schema)


class DataFileError(StageError, ValueError):
    """A data file that cannot be read, or is not the kind, domain or task its reader needs; names the file."""


class MissingDataFile(DataFileError, FileNotFoundError):
    """A data file that is not there (still a FileNotFoundError for the callers that catch one)."""


@contextlib.contextmanager
def _readable(path: str | Path) -> Iterator[None]:
    """Turn Arrow's and the OS's read errors into a DataFileError that names the file (a missing file: a
    MissingDataFile)."""
    try:
        yield
    except MissingDataFile:
        raise
    except FileNotFoundError as e:
        if e.errno is None:  # ours (`no Parquet files in <folder>`): its message says it
            raise MissingDataFile(str(e)) from None
        raise MissingDataFile(f"{path} is missing: run the stage that writes it (`dvc repro`)") from None
    except (pa.ArrowException, OSError) as e:  # Arrow's messages may go on for lines (a whole schema)
        raise DataFileError(f"{path}: not a readable Parquet file ({first_line(e)})") from None


def _read_table(path: Path, columns: list[str] | None) -> pa.Table:
    with _readable(path):
        return pq.read_table(path, columns=columns)


def check_identity(path: str | Path, kind: str | None = None, domain: str | None = None,
                   task: str | None = None) -> dict:
    """Check what a data file (or recording directory) holds, by its metadata; returns the metadata.

    ``kind``: 'random', 'demos', 'translated', 'executed'; ``domain``: 'Y', 'R1H', 'HR2'; ``task``: the task's name
    (files of the simulated box push written before tasks were named carry none: they count as 'box_push').
    """
    try:
        with _readable(path):
            meta = read_metadata(path)
    except DataFileError:
        raise
    except ValueError as e:
        raise DataFileError(str(e)) from None
    have = {"kind": meta.get("kind"), "domain": meta.get("domain"), "task": meta.get("task", UNNAMED_TASK)}
    want = {"kind": kind, "domain": domain, "task": task}
    wrong = [f"{k} {have[k]!r} where {v!r} is needed" for k, v in want.items() if v is not None and have[k] != v]
    if wrong:
        raise DataFileError(f"{path} holds {have['kind']} data of domain {have['domain']} ({', '.join(wrong)})")
    return meta


def read_transitions(path: str | Path, columns: list[str] | None = None, *, kind: str | None = None,
                     domain: str | None = None, task: str | None = None) -> pd.DataFrame:
    """Read a transitions file, or a directory of per-episode files, (optionally some columns) into a DataFrame.

    ``kind``, ``domain``, ``task``: what the file must hold (:func:`check_identity`), checked before reading.
    """
    if kind is not None or domain is not None or task is not None:
        check_identity(path, kind, domain, task)
    if columns is not None:
        with _readable(path):
            have = pq.read_schema(_first_file(path)).names
        missing = [c for c in columns if c not in have]
        if missing:
            raise DataFileError(f"{path}: missing columns {missing}")
    if Path(path).is_dir():
        with _readable(path):
            files = _directory_files(Path(path))
        tables = [_read_table(f, columns).to_pandas() for f in files]
        _check_episodes_apart(files, tables)
        df = pd.concat(tables, ignore_index=True)
    else:
        df = _read_table(Path(path), columns).to_pandas()
    if df.empty:
        raise DataFileError(f"{path}: holds no transitions (0 rows)")
    check_finite(df, path)
    return df


def _check_episodes_apart(files: list[Path], tables: list[pd.DataFrame]) -> None:
    """A DataFileError naming two files of a directory that hold the same episode index: read together, their rows
    would count as one episode (a recording's files copied or renamed into another one)."""
    if "episode_index" not in tables[0].columns:
        return
    owner: dict[int, Path] = {}
    for f, t in zip(files, tables):
        for e in np.unique(t["episode_index"].to_numpy()):
            if int(e) in owner:
                raise DataFileError(f"{f} and {owner[int(e)].name} beside it both hold episode {int(e)}: each episode "
                                    f"of a directory is in one file (a file copied or renamed from another "
                                    f"recording? record into the folder itself, numbering goes on)")
            owner[int(e)] = f


MEASURED_PREFIXES = (layout.STATE_PREFIX, layout.NEXT_STATE_PREFIX, layout.ACTION_PREFIX, layout.HUMAN_ACTION_PREFIX)
"""Columns that hold measurements or commands: every value must be a finite number."""


def check_finite(df: pd.DataFrame, path: str | Path) -> None:
    """DataFileError naming the file, the first column and the row (episode, frame) holding a NaN or an infinity
    among the state, action and next-state columns."""
    cols = [c for c in df.columns if c.startswith(MEASURED_PREFIXES)]
    if not cols:
        return
    values = df[cols].to_numpy(np.float64)
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = (int(i) for i in np.argwhere(bad)[0])
        where = f"row {row}"
        if "episode_index" in df.columns and "frame_index" in df.columns:
            where += f" (episode {df['episode_index'].iloc[row]}, frame {df['frame_index'].iloc[row]})"
        raise DataFileError(f"{path}: column {cols[col]} is {values[row, col]} at {where}; transitions must be "
                            f"finite ({int(bad.sum())} values are not)")


def columns_of(df: pd.DataFrame | pa.Schema, prefix: str, names: list[str]) -> list[str]:
    """Full column names for short layout names under a prefix, checking that they exist."""
    have = df.names if isinstance(df, pa.Schema) else list(df.columns)
    full = [prefix + n for n in names]
    missing = [c for c in full if c not in have]
    if missing:
        raise KeyError(f"missing columns {missing}")
    return full


def check_transitions(path: str | Path, kind: str, domain: str, tl: layout.TaskLayout) -> dict:
    """Validate a transitions file's identity (:func:`check_identity`) and its schema against the layout; returns
    its metadata. Raises DataFileError, naming the file."""
    meta = check_identity(path, kind, domain, tl.name)
    with _readable(path):
        schema = pq.read_schema(_first_file(path))
    problems = []
    expected = list(INDEX_COLUMNS)
    expected += [layout.STATE_PREFIX + c for c in tl.state_columns(domain)]
    if kind == "random":
        expected += [layout.ACTION_PREFIX + c for c in tl.action_columns(domain)]
    else:
        robot = layout.robot_arm(domain)
        expected += [layout.ACTION_PREFIX + c for c in tl.arm_action_columns(robot)]
        if tl.hand_actions_recorded:
            expected += [layout.HUMAN_ACTION_PREFIX + c for c in tl.arm_action_columns("h")]
    expected += [layout.NEXT_STATE_PREFIX + c for c in tl.state_columns(domain)]
    missing = [c for c in expected if c not in schema.names]
    if missing:
        problems.append(f"missing columns {missing}")
    for f in schema:
        if f.name in expected and not (f.metadata or {}).get(b"description"):
            problems.append(f"column {f.name} has no description")
    if problems:
        raise DataFileError(f"{path}: " + "; ".join(problems))
    read_transitions(path, expected)  # every expected column: rows there, and every value finite
    return meta


def demo_subset(path: str | Path, n: int, seed: int, purpose_key: str) -> list[int]:
    """The episode indices of ``n`` demonstrations drawn from a demos file for a training seed.

    The draw depends only on (seed, purpose_key, the file's episodes), so translation and BC of the same
    seed use the same subset. ``n`` equal to the number available takes them all.
    """
    episodes = np.unique(read_transitions(path, columns=["episode_index"], kind="demos").episode_index.to_numpy())
    if n > len(episodes):
        raise DataFileError(f"{n} demonstrations asked for (grid.demos) but {path} holds only {len(episodes)} "
                            f"(demos.per_pairing)")
    key = [seed] + [ord(c) for c in purpose_key]
    rng = np.random.default_rng(key)
    return sorted(int(e) for e in rng.choice(episodes, size=n, replace=False))
