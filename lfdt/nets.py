"""Networks and normalisation shared by the dynamics models, the translator and the BC policies."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import torch
from torch import nn

from lfdt.errors import DeviceError, StageError


def mlp(in_dim: int, out_dim: int, hidden: list[int], slope: float = 0.2) -> nn.Sequential:
    """Fully connected net: len(hidden) hidden layers with leaky ReLU, then a linear output layer."""
    layers: list[nn.Module] = []
    d = in_dim
    for h in hidden:
        layers += [nn.Linear(d, h), nn.LeakyReLU(slope)]
        d = h
    layers.append(nn.Linear(d, out_dim))
    return nn.Sequential(*layers)


class Normalizer(nn.Module):
    """Per-dimension z-score with a floor on the standard deviation (stored as buffers, saved with state dicts)."""

    def __init__(self, mean: np.ndarray, std: np.ndarray, names: list[str] | None = None):
        super().__init__()
        self.register_buffer("mean", torch.as_tensor(np.asarray(mean), dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(np.asarray(std), dtype=torch.float32))
        self.names = list(names) if names is not None else None

    @classmethod
    def fit(cls, x: np.ndarray, std_floor: float, names: list[str] | None = None) -> Normalizer:
        """Statistics of data x (rows = samples)."""
        return cls(x.mean(axis=0), np.maximum(x.std(axis=0), std_floor), names)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean) / self.std

    def inverse(self, z: torch.Tensor) -> torch.Tensor:
        return z * self.std + self.mean

    def to_dict(self) -> dict:
        return {"mean": self.mean.tolist(), "std": self.std.tolist(), "names": self.names}



def save_state(module: nn.Module, path: str | Path, config: dict) -> None:
    """Save a state dict and a JSON config beside it (``<name>.pt`` and ``<name>.json``), atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    torch.save(module.state_dict(), tmp)
    os.replace(tmp, path)
    cfg_path = path.with_suffix(".json")
    tmp = cfg_path.with_name(f".{cfg_path.name}.tmp")
    tmp.write_text(json.dumps(config, indent=2) + "\n")
    os.replace(tmp, cfg_path)


def load_state(module: nn.Module, path: str | Path) -> nn.Module:
    """Load a state dict saved by :func:`save_state` (``weights_only=True``) into module; eval mode."""
    module.load_state_dict(torch.load(path, weights_only=True, map_location="cpu"))
    return module.eval()


def read_config(path: str | Path) -> dict:
    """The JSON config beside a saved state dict."""
    return json.loads(Path(path).with_suffix(".json").read_text())


def batches(n: int, batch_size: int, generator: torch.Generator) -> torch.Tensor:
    """Indices of one random minibatch (sampling with replacement across iterations)."""
    return torch.randint(0, n, (batch_size,), generator=generator)


class TrainingDiverged(StageError):
    """A loss became NaN or infinite: the run stops there instead of finishing on garbage."""


def check_finite(value: float, what: str, iteration: int) -> float:
    """``value`` if finite; otherwise TrainingDiverged naming the loss and the iteration."""
    if not math.isfinite(value):
        raise TrainingDiverged(f"{what} is {value} at iteration {iteration}: training diverged (lower its "
                               f"learning_rate, or look for NaN or infinite values in its input data)")
    return value


def torch_device(name: str) -> torch.device:
    """The torch device ``params.yaml``'s ``device`` names, checked to exist here (a clear error, not a CUDA
    traceback after the data has loaded)."""
    dev = torch.device(name)
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise DeviceError(f"params.yaml: device = {name!r}, but torch {torch.__version__} finds no CUDA device on "
                              "this machine (torch.cuda.is_available() is False); set device: cpu")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise DeviceError(f"params.yaml: device = {name!r}, but this machine has {torch.cuda.device_count()} "
                              "CUDA device(s), numbered from 0")
    elif dev.type == "mps" and not torch.backends.mps.is_available():
        raise DeviceError(f"params.yaml: device = {name!r}, but torch finds no MPS device on this machine; "
                          "set device: cpu")
    return dev
