"""Recordings written one episode at a time, atomically, in the project's Parquet conventions.

A recording is a directory of ``episode_NNNNNN.parquet`` files (each a transitions table, see
:mod:`lfdt.data`) plus ``_meta.json`` (readers of Parquet datasets skip names starting with ``_``).
An episode is written only when it ends, to a temporary name and then renamed, so a crash or Ctrl-C
loses at most the episode in progress and never leaves a half-written file under a final name.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from lfdt import data

EPISODE_GLOB = "episode_*.parquet"


class EpisodeRecorder:
    """Collects the transitions of one episode at a time and writes each finished episode atomically."""

    def __init__(self, out_dir: str | Path, schema: pa.Schema, dt: float):
        self.dir = Path(out_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.schema = schema
        self.dt = dt
        meta = self.dir / "_meta.json"
        if not meta.exists():
            tmp = self.dir / "._meta.json.tmp"
            tmp.write_text(json.dumps(data.read_schema_metadata(schema), indent=2))
            os.replace(tmp, meta)
        self._rows: list[tuple] | None = None

    def next_index(self) -> int:
        """Index of the next episode (recordings can be resumed: numbering continues after existing files)."""
        done = sorted(self.dir.glob(EPISODE_GLOB))
        return int(done[-1].stem.split("_")[1]) + 1 if done else 0

    def start(self) -> int:
        """Begin an episode; returns its index."""
        self._rows = []
        self._index = self.next_index()
        return self._index

    def add(self, state, action, next_state, human_action=None, **extra) -> None:
        """Append one transition to the episode in progress."""
        if self._rows is None:
            raise RuntimeError("add() outside an episode: call start() first")
        self._rows.append((np.asarray(state, float), np.asarray(action, float), np.asarray(next_state, float),
                           None if human_action is None else np.asarray(human_action, float), extra))

    def finish(self) -> Path | None:
        """Write the episode in progress (if it has any transition) and return its path."""
        rows, self._rows = self._rows, None
        if not rows:
            return None
        n = len(rows)
        extra_names = list(rows[0][4])
        table = data.transitions_table(
            self.schema, episode_index=np.full(n, self._index), frame_index=np.arange(n), dt=self.dt,
            states=np.stack([r[0] for r in rows]), actions=np.stack([r[1] for r in rows]),
            next_states=np.stack([r[2] for r in rows]),
            human_actions=None if rows[0][3] is None else np.stack([r[3] for r in rows]),
            extra={k: np.array([r[4][k] for r in rows]) for k in extra_names})
        return data.write_table(table, self.dir / f"episode_{self._index:06d}.parquet")

    def abort(self) -> None:
        """Drop the episode in progress (nothing is written)."""
        self._rows = None


def read_recording(directory: str | Path) -> pd.DataFrame:
    """All finished episodes of a recording, in order (an unfinished episode never has a file)."""
    files = sorted(Path(directory).glob(EPISODE_GLOB))
    if not files:
        raise FileNotFoundError(f"no finished episodes ({EPISODE_GLOB}) in {directory}")
    return data.read_transitions(directory)
