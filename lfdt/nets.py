"""Networks and normalisation shared by the dynamics models, the translator and the BC policies."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as nnf
from torch import nn

from lfdt import numerics
from lfdt.errors import DeviceError, StageError, first_line


def matmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``a @ b`` with autograd, for (batched) matrices of float32 on the CPU; broadcasts like :func:`torch.matmul`.

    While the numeric code paths are pinned (:mod:`lfdt.numerics`), the product is OpenBLAS's, with the kernels that
    ``OPENBLAS_CORETYPE`` fixes: MKL's GEMM, which torch would call, takes other code paths on Intel and on AMD CPUs
    unless slowed to SSE2. Each matrix of a batch is one GEMM of its own shape, so a seed's product is the same bits
    whether its weights stand alone or in a stack of seeds. Elsewhere (``LFDT_NUMERICS=native``, a GPU) it is
    :func:`torch.matmul`.
    """
    if not numerics.pinned() or a.device.type != "cpu" or b.device.type != "cpu" or a.dtype != torch.float32:
        return torch.matmul(a, b)
    return _BlasMatmul.apply(a, b)


def _blas(x: torch.Tensor) -> np.ndarray:
    """A NumPy view of x that NumPy's matmul hands to BLAS (unit stride in one of its last two dimensions); a copy
    otherwise, since NumPy would fall back to its own loop, whose sums are ordered differently."""
    arr = x.detach().numpy()
    if arr.ndim < 2:
        return arr
    item = arr.itemsize
    s_row, s_col = arr.strides[-2], arr.strides[-1]
    if (s_col == item and s_row >= max(1, arr.shape[-1]) * item) or \
            (s_row == item and s_col >= max(1, arr.shape[-2]) * item):
        return arr
    return np.ascontiguousarray(arr)


def _reduce_to(grad: torch.Tensor, shape: torch.Size) -> torch.Tensor:
    """Sum a broadcast gradient back to the shape of its input (batch dimensions only)."""
    while grad.dim() > len(shape):
        grad = grad.sum(0)
    for d, n in enumerate(shape[:-2]):
        if n == 1 and grad.shape[d] != 1:
            grad = grad.sum(d, keepdim=True)
    return grad


class _BlasMatmul(torch.autograd.Function):
    # forward(ctx, ...) rather than setup_context: torch binds the arguments of the latter with inspect on every call,
    # which costs more than a small product itself
    @staticmethod
    def forward(ctx, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(a, b)
        return torch.from_numpy(np.matmul(_blas(a), _blas(b)))

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        a, b = ctx.saved_tensors
        ga = gb = None
        if ctx.needs_input_grad[0]:
            ga = _reduce_to(_BlasMatmul.apply(grad, b.transpose(-1, -2)), a.shape)
        if ctx.needs_input_grad[1]:
            gb = _reduce_to(_BlasMatmul.apply(a.transpose(-1, -2), grad), b.shape)
        return ga, gb


def linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None = None) -> torch.Tensor:
    """:func:`torch.nn.functional.linear` (weight ``(out, in)``) through :func:`matmul`."""
    y = matmul(x.reshape(-1, x.shape[-1]), weight.t()).reshape(*x.shape[:-1], weight.shape[0])
    return y if bias is None else y + bias


class PinnedLinear(nn.Linear):
    """:class:`torch.nn.Linear` whose product goes through :func:`matmul` (same parameters and state dict)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return linear(x, self.weight, self.bias)


def pin_linear_layers(module: nn.Module) -> nn.Module:
    """Turn every :class:`torch.nn.Linear` inside ``module`` into a :class:`PinnedLinear` in place, keeping its
    parameter objects (so an optimiser built on them still steps them): for networks built by other libraries
    (stable-baselines3's SAC)."""
    for child in list(module.children()):
        if type(child) is nn.Linear:
            child.__class__ = PinnedLinear
        else:
            pin_linear_layers(child)
    return module


class StackedLinear(nn.Module):
    """``n`` independent linear layers (one per seed) as one: weight ``(n, in, out)``, bias ``(n, 1, out)``; maps
    ``(n, batch, in)`` to ``(n, batch, out)`` with one GEMM per member."""

    def __init__(self, n: int, d_in: int, d_out: int):
        super().__init__()
        self.weight = nn.Parameter(torch.zeros(n, d_in, d_out))
        self.bias = nn.Parameter(torch.zeros(n, 1, d_out))

    def reset_member(self, k: int, generator: torch.Generator | None) -> None:
        """Initialise member k as :class:`torch.nn.Linear` does (uniform in +-1/sqrt(in)), from ``generator`` (None:
        torch's global one)."""
        bound = 1.0 / math.sqrt(self.weight.shape[1])
        with torch.no_grad():
            self.weight[k].copy_(torch.rand(self.weight.shape[1:], generator=generator) * (2 * bound) - bound)
            self.bias[k].copy_(torch.rand(self.bias.shape[1:], generator=generator) * (2 * bound) - bound)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return matmul(x, self.weight) + self.bias


class StackedMLP(nn.Module):
    """``n`` fully connected nets of the same shape (one per seed), trained as one: len(hidden) hidden layers with
    leaky ReLU, then a linear output layer; ``(n, batch, in)`` -> ``(n, batch, out)``. With ``n`` = 1 it is one
    net. Member k's parameters, its outputs and their gradients do not depend on the other members."""

    def __init__(self, n: int, in_dim: int, out_dim: int, hidden: list[int], slope: float = 0.2,
                 generators: list[torch.Generator] | None = None, init: bool = True):
        super().__init__()
        dims = [in_dim, *hidden, out_dim]
        self.layers = nn.ModuleList(StackedLinear(n, a, b) for a, b in zip(dims[:-1], dims[1:]))
        self.slope = slope
        self.n = n
        if generators is not None and len(generators) != n:
            raise ValueError(f"{len(generators)} generators for {n} stacked nets")
        # member by member, layer by layer: a member's initial weights do not depend on the others
        for k, g in enumerate((generators or [None] * n) if init else []):
            for layer in self.layers:
                layer.reset_member(k, g)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(n, batch, in)`` -> ``(n, batch, out)``; a stack of one also takes ``(batch, in)`` -> ``(batch, out)``."""
        flat = x.dim() == 2
        if flat:
            if self.n != 1:
                raise ValueError(f"a stack of {self.n} nets needs input of shape (n, batch, in), got {tuple(x.shape)}")
            x = x[None]
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < len(self.layers) - 1:
                x = nnf.leaky_relu(x, self.slope)
        return x[0] if flat else x

    def member(self, k: int) -> StackedMLP:
        """Member k as a stack of one (weights copied)."""
        one = StackedMLP(1, self.layers[0].weight.shape[1], self.layers[-1].weight.shape[2],
                         [layer.weight.shape[2] for layer in self.layers[:-1]], self.slope, init=False)
        one.load_member_state(0, self.member_state(k))
        return one.to(self.layers[0].weight.device)

    def member_state(self, k: int) -> dict[str, torch.Tensor]:
        """Member k's parameters as the state dict of a stack of one (cloned)."""
        return {name: t[k:k + 1].detach().clone() for name, t in self.state_dict().items()}

    def load_member_state(self, k: int, state: dict[str, torch.Tensor]) -> None:
        """Put a stack-of-one state dict (:meth:`member_state`) into member k."""
        with torch.no_grad():
            for name, t in self.state_dict().items():
                t[k:k + 1].copy_(state[name])


def sin_cos(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(sin x, cos x) with autograd; while pinned, from NumPy's float32 loops (torch would call MKL's vector math,
    whose code path is MKL's choice per CPU)."""
    if not numerics.pinned() or x.device.type != "cpu" or x.dtype != torch.float32:
        return torch.sin(x), torch.cos(x)
    return _NumpySinCos.apply(x)


class _NumpySinCos(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        a = x.detach().numpy()
        sin, cos = torch.from_numpy(np.sin(a)), torch.from_numpy(np.cos(a))
        ctx.save_for_backward(sin, cos)
        return sin, cos

    @staticmethod
    def backward(ctx, g_sin: torch.Tensor, g_cos: torch.Tensor) -> torch.Tensor:
        sin, cos = ctx.saved_tensors
        return g_sin * cos - g_cos * sin


def softplus(x: torch.Tensor) -> torch.Tensor:
    """log(1 + e^x) with autograd; while pinned, in NumPy, whose loops give every element the same code whatever its
    place in the tensor. torch's kernel computes the elements of a vector body with SLEEF's exp and those of the
    scalar tail with libm's, so a seed's loss would depend on where its rows sit in a stack of seeds."""
    if not numerics.pinned() or x.device.type != "cpu" or x.dtype != torch.float32:
        return nnf.softplus(x)
    return _NumpySoftplus.apply(x)


class _NumpySoftplus(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(x)
        a = x.detach().numpy()
        return torch.from_numpy(np.maximum(a, np.float32(0)) + np.log1p(np.exp(-np.abs(a))))

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:
        a = ctx.saved_tensors[0].detach().numpy()
        e = np.exp(-np.abs(a))
        one = np.float32(1)
        sigmoid = np.where(a >= 0, one / (one + e), e / (one + e))
        return grad * torch.from_numpy(sigmoid)


def mlp(in_dim: int, out_dim: int, hidden: list[int], slope: float = 0.2,
        generator: torch.Generator | None = None) -> StackedMLP:
    """One fully connected net (a :class:`StackedMLP` of one); input ``(batch, in)`` or ``(1, batch, in)``."""
    return StackedMLP(1, in_dim, out_dim, hidden, slope, None if generator is None else [generator])


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


class ModelFileError(StageError):
    """A saved model that cannot be loaded: names the file and what is wrong with it."""


def load_state(module: nn.Module, path: str | Path) -> nn.Module:
    """Load a state dict saved by :func:`save_state` (``weights_only=True``) into module; eval mode. A file that is
    missing, truncated, not a state dict or one of another model raises :class:`ModelFileError` naming it."""
    path = Path(path)
    try:
        state = torch.load(path, weights_only=True, map_location="cpu")
    except FileNotFoundError:
        raise ModelFileError(f"{path} is missing") from None
    except Exception as err:  # noqa: BLE001 - torch raises many kinds for a damaged file; each is this one error
        raise ModelFileError(f"{path} is not a saved state dict (truncated or another kind of file: "
                             f"{type(err).__name__}: {first_line(err)})") from None
    if not isinstance(state, dict):
        raise ModelFileError(f"{path} holds a {type(state).__name__}, not a state dict")
    try:
        module.load_state_dict(state)
    except RuntimeError as err:
        raise ModelFileError(f"{path} holds the weights of another model than a {type(module).__name__} "
                             f"({first_line(err)})") from None
    return module.eval()


def read_config(path: str | Path) -> dict:
    """The JSON config beside a saved state dict; :class:`ModelFileError` names it when it is missing or not JSON."""
    cfg = Path(path).with_suffix(".json")
    try:
        out = json.loads(cfg.read_text())
    except FileNotFoundError:
        raise ModelFileError(f"{cfg} is missing: every saved model has its config beside it ({Path(path).name} was "
                             "copied without it, or saved by something else)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ModelFileError(f"{cfg} is not JSON ({err})") from None
    if not isinstance(out, dict):
        raise ModelFileError(f"{cfg} holds a JSON {type(out).__name__}, not a model's config")
    return out


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
