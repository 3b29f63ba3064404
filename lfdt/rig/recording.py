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

from lfdt import data, inputs
from lfdt.files import temp_path

EPISODE_GLOB = "episode_*.parquet"
IDENTITY = ("kind", "domain", "task")
"""Metadata every episode of one recording folder shares."""


class RecordingMismatch(ValueError):
    """A recording folder that already holds another kind, domain or task."""


class EpisodeRecorder:
    """Collects the transitions of one episode at a time and writes each finished episode atomically."""

    def __init__(self, out_dir: str | Path, schema: pa.Schema, dt: float):
        self.dir = Path(out_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.schema = schema
        self.dt = dt
        meta = self.dir / "_meta.json"
        mine = data.read_schema_metadata(schema)
        if meta.exists():
            # written by this class, but a folder given by the user may hold anything under that name
            theirs = inputs.json_object(meta, "recording folder's", "the metadata a recording started with (or "
                                        "choose another --out)")
            for key in IDENTITY:
                if theirs.get(key) != mine.get(key):
                    raise RecordingMismatch(f"{self.dir} holds a recording of {key} {theirs.get(key)!r}, not "
                                            f"{mine.get(key)!r}: one folder holds one kind, domain and task (choose "
                                            f"another --out)")
        else:
            tmp = temp_path(meta)
            tmp.write_text(json.dumps(mine, indent=2))
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


def record_random_episode(rig, rec: EpisodeRecorder, rng: np.random.Generator, steps: int, reach: float,
                          hold_max: int) -> int:
    """One episode of random motion on a reset rig, recorded into ``rec`` (started by the caller, finished here).

    Every ``1..hold_max`` steps each slot gets a new target, a uniform offset of up to ``reach`` m per axis from
    its end; the robots are sent theirs, the human slot's is offered to the rig (the twin's random person moves
    there; a real person moves freely and the rig records the hand's measured motion). Returns the steps taken.
    """
    obs = rig.observe()
    rel, hold = np.zeros((2, 2)), 0
    for _ in range(steps):
        if hold == 0:
            rel = rng.uniform(-reach, reach, size=(2, 2))
            hold = int(rng.integers(1, hold_max + 1))
        rig.act({arm: rel[slot] for slot, arm in enumerate(rig.slots) if arm != "h"},
                human_target=None if rig.human_slot is None else rel[rig.human_slot])
        nxt = rig.observe()
        action = np.array([rig.human_action(obs, nxt) if arm == "h" else rel[slot]
                           for slot, arm in enumerate(rig.slots)])
        rec.add(obs, action.reshape(-1), nxt)
        obs, hold = nxt, hold - 1
    rec.finish()
    return steps


def record_demo_episode(rig, rec: EpisodeRecorder, program, robot: str, steps: int) -> tuple[bool | None, int]:
    """One demonstration on a reset rig, recorded into ``rec`` (started by the caller, who keeps or drops it).

    ``program`` (:class:`lfdt.tasks.demonstrators.ProgrammedMotion`) gives the robot's absolute targets; the robot's
    action is its commanded target relative to its end, the hand is only observed. Stops at ``steps`` or when the
    rig says the episode is over, then stops the arms. Returns the rig's outcome (None: the rig cannot tell) and
    the steps taken.
    """
    slot = rig.slots.index(robot)
    obs = rig.observe()
    n = 0
    while n < steps:
        rel = program.next_target() - obs[2 * slot:2 * slot + 2]
        rig.act({robot: rel})
        nxt = rig.observe()
        rec.add(obs, rel, nxt)
        obs, n = nxt, n + 1
        if rig.done:
            break
    rig.stop()  # the arm holds while the outcome is decided
    return rig.outcome(), n
