"""G's input data: the canonical X columns of a pairing, and its transitions (loading, held-out split)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfdt import data, layout
from lfdt.config import held_out_count
from lfdt.errors import StageError
from lfdt.layout import TaskLayout

PAIRING_INDEX = {p: i for i, p in enumerate(layout.PAIRINGS)}


def canonical_x_columns(pairing: str, tl: TaskLayout) -> list[str]:
    """G's input columns of a pairing: the robot that is there, the human stand-in, the object."""
    return tl.canonical_x_columns(pairing)


@dataclass
class Transitions:
    """Consecutive state pairs of one pairing in canonical X order (raw units)."""

    x: np.ndarray
    x2: np.ndarray
    episode: np.ndarray
    frame: np.ndarray
    a: np.ndarray | None = None
    """The real robot's recorded action (demonstrations; diagnostics only, never trained on)."""
    x_prev: np.ndarray | None = None
    """The state one step before x (x itself at an episode's first frame); None means x."""

    def subset(self, m: np.ndarray) -> Transitions:
        """The transitions selected by a boolean mask or index array."""
        return Transitions(self.x[m], self.x2[m], self.episode[m], self.frame[m],
                           None if self.a is None else self.a[m], None if self.x_prev is None else self.x_prev[m])


def load_x_transitions(path, pairing: str, episodes: list[int] | None = None, *, tl: TaskLayout,
                       with_actions: bool = False, kind: str) -> Transitions:
    """State pairs of an X dataset (``kind`` 'random' or 'demos', checked), canonical column order, optionally some
    episodes only; ``with_actions`` also reads the real robot's recorded action (for diagnostics)."""
    cols = tl.canonical_x_columns(pairing)
    a_cols = [layout.ACTION_PREFIX + c for c in tl.arm_action_columns(layout.robot_arm(pairing))]
    names = ["episode_index", "frame_index"] + [layout.STATE_PREFIX + c for c in cols] + \
        [layout.NEXT_STATE_PREFIX + c for c in cols] + (a_cols if with_actions else [])
    df = data.read_transitions(path, columns=names, kind=kind, domain=pairing, task=tl.name)
    if episodes is not None:
        df = df[df.episode_index.isin(episodes)]
    df = df.sort_values(["episode_index", "frame_index"], kind="stable")
    x = np.array(df[[layout.STATE_PREFIX + c for c in cols]].to_numpy(np.float32))
    episode = df.episode_index.to_numpy()
    first = np.r_[True, episode[1:] != episode[:-1]]
    x_prev = np.where(first[:, None], x, np.roll(x, 1, axis=0))
    return Transitions(
        x=x, x2=np.array(df[[layout.NEXT_STATE_PREFIX + c for c in cols]].to_numpy(np.float32)),
        episode=episode, frame=df.frame_index.to_numpy(),
        a=df[a_cols].to_numpy(np.float32) if with_actions else None, x_prev=x_prev)


def split_held_out(sets: dict[str, Transitions], fraction: float, seed: int
                   ) -> tuple[dict[str, Transitions], dict[str, Transitions] | None]:
    """Split each pairing's demonstrations by whole episodes: (training, held out for checkpoint selection).

    ``fraction`` 0 holds nothing out (returns None); otherwise at least one episode per pairing is held out.
    """
    if fraction <= 0:
        return sets, None
    train, held = {}, {}
    rng = np.random.default_rng([seed, 7])
    for p, t in sets.items():
        eps = np.unique(t.episode)
        n = held_out_count(len(eps), fraction)
        if n >= len(eps):
            raise StageError(f"{p}: {len(eps)} demonstration(s) cannot be split for translator.holdout_fraction "
                             f"{fraction:g} ({n} held out, none left to train on)")
        out = np.isin(t.episode, rng.choice(eps, size=n, replace=False))
        train[p], held[p] = t.subset(~out), t.subset(out)
    return train, held
