"""Adam whose every step is the same bits on every CPU, and for every stack of seeds.

torch's Adam takes its square root from MKL's vector math, which on AVX-512 AMD CPUs gives other bits than
elsewhere whatever ``MKL_CBWR`` says (:mod:`lfdt.numerics`), and its fused element-wise kernels may treat the
elements of a vector body and of its scalar tail differently, so that a seed's update could depend on where its
parameters sit in a stack of seeds. This Adam does its element-wise arithmetic in NumPy (IEEE operations one at a
time, no fused multiply-add, a correctly rounded square root) on the parameters' memory, in place. With
``LFDT_NUMERICS=native`` or on a GPU it is torch's Adam.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import torch

from lfdt import numerics

_DYNAMO_WRAPPED = ("add_param_group", "zero_grad", "state_dict", "load_state_dict")
"""The methods of :class:`torch.optim.Optimizer` that torch wraps in ``torch._disable_dynamo``."""


def _without_dynamo_import() -> None:
    """Let every optimizer's first ``add_param_group`` (its construction), ``zero_grad``, ``state_dict`` and
    ``load_state_dict`` skip importing ``torch._dynamo``. torch wraps those four in ``torch._disable_dynamo``, which
    imports the compiler (about 1.5 s of CPU, in every worker process of every training stage) to mark them as not
    to be compiled, and caches the result on the function as ``__dynamo_disable``. The project never compiles, so
    the cache is set to the function itself: eager calls run the same code, the same bits (tests/test_optim.py)."""
    for name in _DYNAMO_WRAPPED:
        inner = getattr(getattr(torch.optim.Optimizer, name), "__wrapped__", None)
        if inner is not None and getattr(inner, "__dynamo_disable", None) is None:
            setattr(inner, "__dynamo_disable", inner)


_without_dynamo_import()


class _NumpyAdam(torch.optim.Optimizer):
    """Adam (Kingma & Ba) on CPU float32 parameters, arithmetic in NumPy; no weight decay, no amsgrad."""

    def __init__(self, params: Iterable[torch.nn.Parameter], lr: float = 1e-3,
                 betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8):
        if not lr > 0 or not eps > 0 or not all(0 <= b < 1 for b in betas):
            raise ValueError(f"Adam: lr {lr}, betas {betas}, eps {eps} out of range")
        super().__init__(params, {"lr": lr, "betas": tuple(betas), "eps": eps})

    def _scratch(self, p: torch.Tensor, like: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if not hasattr(self, "_tmp"):
            self._tmp: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        bufs = self._tmp.get(id(p))
        if bufs is None or bufs[0].shape != like.shape:
            bufs = (np.empty_like(like), np.empty_like(like))
            self._tmp[id(p)] = bufs
        return bufs

    @torch.no_grad()
    def step(self, closure=None):
        loss = None if closure is None else closure()
        for group in self.param_groups:
            b1, b2 = group["betas"]
            for p in group["params"]:
                if p.grad is None:
                    continue
                if p.device.type != "cpu" or p.dtype != torch.float32:
                    raise TypeError("lfdt.optim.Adam steps float32 parameters on the CPU only")
                state = self.state[p]
                if not state:
                    state["step"] = 0
                    state["exp_avg"] = torch.zeros_like(p, memory_format=torch.contiguous_format)
                    state["exp_avg_sq"] = torch.zeros_like(p, memory_format=torch.contiguous_format)
                state["step"] += 1
                t = state["step"]
                g = p.grad.detach().numpy()
                m = state["exp_avg"].numpy()
                v = state["exp_avg_sq"].numpy()
                x = p.detach().numpy()
                # two scratch arrays per parameter, kept outside the state (not saved with it); every operation
                # below writes into them, so a step allocates nothing
                tmp, tmp2 = self._scratch(p, g)
                f32 = np.float32
                # m = b1 m + (1 - b1) g;  v = b2 v + (1 - b2) g^2
                m *= f32(b1)
                np.multiply(f32(1 - b1), g, out=tmp)
                m += tmp
                v *= f32(b2)
                np.multiply(g, g, out=tmp)
                np.multiply(f32(1 - b2), tmp, out=tmp)
                v += tmp
                # x -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)
                np.sqrt(v, out=tmp)
                tmp /= f32(math.sqrt(1 - b2 ** t))
                tmp += f32(group["eps"])
                np.divide(m, tmp, out=tmp2)
                tmp2 *= f32(group["lr"] / (1 - b1 ** t))
                x -= tmp2
        return loss


def Adam(params: Iterable[torch.nn.Parameter], lr: float = 1e-3, betas: tuple[float, float] = (0.9, 0.999),
         eps: float = 1e-8, **kwargs) -> torch.optim.Optimizer:
    """Adam: NumPy arithmetic while the numeric code paths are pinned, torch's Adam otherwise (or with options only
    torch's has, such as ``weight_decay``). Takes the arguments of :class:`torch.optim.Adam`, so it can stand in for
    it (stable-baselines3's ``optimizer_class``)."""
    params = list(params)
    on_cpu = all(p.device.type == "cpu" for p in _flat(params))
    if numerics.pinned() and on_cpu and not any(v for v in kwargs.values()):
        return _NumpyAdam(params, lr=lr, betas=betas, eps=eps)
    return torch.optim.Adam(params, lr=lr, betas=betas, eps=eps, **kwargs)


def _flat(params: list) -> list[torch.Tensor]:
    out = []
    for p in params:
        out.extend(p["params"] if isinstance(p, dict) else [p])
    return out
