"""Resumable translator training: the whole state of one stack's training in one file, so that a stage killed (a
crash, Ctrl-C, a machine that restarts) goes on from its last checkpoint instead of from iteration 1, with the same
bits as a run never stopped (tests/test_translation.py).

A checkpoint is written atomically every ``translator.select_every`` iterations, as a state dict (tensors, numbers,
lists; loaded with ``weights_only=True``). It is read back only by a run with the same key: the translator's config,
the members' seeds, every array it trains on and F, F^-1's weights. The stage removes it once the translators are
saved. It lives outside DVC's outputs (``paths.translator_checkpoints``, git-ignored), so `dvc repro` never removes
it before the stage runs again.
"""

from __future__ import annotations

import hashlib
import json
import pickle
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lfdt.config import TranslatorConfig
from lfdt.errors import first_line
from lfdt.files import write_atomic
from lfdt.translation.transitions import Transitions

FILE = "checkpoint.pt"


def _arrays_of(t: Transitions | None) -> list[np.ndarray]:
    if t is None:
        return []
    return [a for a in (t.x, t.x2, t.episode, t.frame, t.x_prev) if a is not None]


def run_key(cfg: TranslatorConfig, seeds: list[int], demos: list[dict[str, Transitions]],
            held_out: list[dict[str, Transitions] | None], random_x: dict[str, Transitions], y_random: np.ndarray,
            modules: list[torch.nn.Module], device: str) -> str:
    """A hash of everything a stack's training depends on: a checkpoint resumes only the run it was written by.
    ``modules``: the untrained translator (its initial weights, its normalisers, its arms' kinematics) and F, F^-1."""
    h = hashlib.sha256(json.dumps({"cfg": cfg.model_dump(), "seeds": seeds, "device": str(device)},
                                  sort_keys=True).encode())
    sets = [*demos, *(ho or {} for ho in held_out), random_x]
    for s in sets:
        for pairing in sorted(s):
            h.update(pairing.encode())
            for a in _arrays_of(s[pairing]):
                h.update(np.ascontiguousarray(a).tobytes())
    h.update(np.ascontiguousarray(y_random).tobytes())
    for module in modules:
        for name, t in module.state_dict().items():
            h.update(name.encode())
            h.update(t.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()[:32]


class Checkpoint:
    """The checkpoint file of one stack's training in ``folder``, valid for the run whose key is ``key``."""

    def __init__(self, folder: str | Path, key: str):
        self.path = Path(folder) / FILE
        self.key = key

    def load(self) -> dict[str, Any] | None:
        """The saved state of this run, or None (no checkpoint, or one of another run: it is left to be replaced)."""
        if not self.path.is_file():
            return None
        try:
            state = torch.load(self.path, weights_only=True, map_location="cpu")
        except (OSError, RuntimeError, EOFError, ValueError, pickle.UnpicklingError) as e:
            # damaged (written outside write_atomic, or by another torch): it only saves time, so start over
            print(f"{self.path}: not a readable checkpoint ({first_line(e)}); "
                  f"training starts from iteration 1", file=sys.stderr)
            return None
        return state if isinstance(state, dict) and state.get("key") == self.key else None

    def save(self, state: dict[str, Any]) -> None:
        """Write ``state`` (with this run's key) atomically."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(self.path, lambda tmp: torch.save({**state, "key": self.key}, tmp))
