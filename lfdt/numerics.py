"""One numeric code path on every x86-64 CPU with AVX2: imported first, before numpy, torch or mujoco load.

The same code and params gave different Table I's on different CPUs: torch, MKL, oneDNN, NumPy and OpenBLAS each
pick their kernels per CPU (AVX-512 or AVX2, Intel or AMD), the last bits of a float result differ, and adversarial
training grows those bits into different policies. Importing this module (``lfdt/__init__.py`` does, so any
``import lfdt...`` does) sets the environment that fixes those choices, before the libraries read it:

========================  ===============  ============================================================================
variable                  value            what it pins
========================  ===============  ============================================================================
``ATEN_CPU_CAPABILITY``   ``avx2``         torch's own vectorised kernels (random numbers, sigmoid, softplus, ...)
``MKL_CBWR``              ``COMPATIBLE``   MKL's code branch, the one Intel documents for Intel and AMD CPUs alike
``ONEDNN_MAX_CPU_ISA``    ``AVX2``         oneDNN's JIT kernels
``NPY_DISABLE_CPU_FEATURES`` AVX-512 groups  NumPy's SIMD loops (exp, log, arctan2, ...) take their AVX2 versions
``OPENBLAS_CORETYPE``     ``Haswell``      OpenBLAS (NumPy's BLAS) runs its Haswell kernels
``OPENBLAS_NUM_THREADS``  ``1``            and one thread, so its blocking never depends on the core count
========================  ===============  ============================================================================

Two holes remain that no variable closes, measured on an AVX-512 AMD EPYC against the same binaries under QEMU
(``tools/cross_cpu.py``): MKL's GEMM differs between Intel and AMD CPUs unless ``MKL_CBWR=COMPATIBLE``, which halves
its speed, and MKL's vector square root differs on AVX-512 AMD CPUs whatever ``MKL_CBWR`` says. So, while pinned,
matrix products go through OpenBLAS's pinned kernels (:func:`lfdt.nets.matmul`, as fast as MKL's) and Adam takes
its square root from NumPy (:class:`lfdt.optim.Adam`). MuJoCo needs no lever: its results were the same bits with
and without AVX-512. glibc's libm picks its FMA variants on every CPU with AVX2.

One switch turns the pin off, for speed on a machine whose results need not match anyone else's::

    LFDT_NUMERICS=native dvc repro

Then every library picks its own kernels again; results are still the same from run to run on one machine, but no
longer across CPUs (``reports/fingerprint.json`` and its test tell). Every MLflow run is tagged with the mode and the
CPU model (:func:`describe`).
"""

from __future__ import annotations

import os
import platform
import sys

from lfdt.errors import InputError
from lfdt.inputs import env_choice

SWITCH = "LFDT_NUMERICS"
"""Environment variable: ``pinned`` (default) or ``native`` (each library picks its own kernels); another value ends
the importing program at once with one line ``error: ...`` and exit code 2."""

MODES = ("pinned", "native")

PINNED_ENV: dict[str, str] = {
    "ATEN_CPU_CAPABILITY": "avx2",
    "MKL_CBWR": "COMPATIBLE",
    "ONEDNN_MAX_CPU_ISA": "AVX2",
    # NumPy 2.4's dispatch targets above AVX2 (X86_V3); requirements.txt pins the NumPy these names belong to
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",
    "OPENBLAS_CORETYPE": "Haswell",
    "OPENBLAS_NUM_THREADS": "1",
}
"""What :func:`pin` sets (see the module's docstring)."""

_LIBRARIES = ("numpy", "torch", "mujoco", "scipy")
"""Libraries that read the pinned variables when they load."""


class NumericsError(ImportError):
    """The pin cannot take effect (a library loaded first, or the CPU lacks AVX2)."""


def mode() -> str:
    """``pinned`` or ``native``, from :data:`SWITCH`; another value raises :class:`~lfdt.errors.InputError`."""
    return env_choice(SWITCH, MODES, "pinned")


def pinned() -> bool:
    """Whether the numeric code paths are pinned in this process."""
    return mode() == "pinned"


def cpu_model() -> str:
    """The CPU's model name as /proc/cpuinfo gives it (the platform's processor string elsewhere)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cpu_flags() -> set[str]:
    """The CPU's feature flags from /proc/cpuinfo (empty where there is none)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def isa() -> str:
    """The widest vector ISA of this CPU that the pin cares about: ``avx512``, ``avx2`` or ``other``."""
    flags = cpu_flags()
    if "avx512f" in flags:
        return "avx512"
    return "avx2" if {"avx2", "fma"} <= flags else "other"


def pin() -> None:
    """Set :data:`PINNED_ENV` (when pinned), or fail saying why it cannot take effect."""
    if not pinned():
        return
    if platform.machine().lower() not in ("x86_64", "amd64"):
        raise NumericsError(f"the numeric pin is for x86-64 CPUs; this is {platform.machine()}: set {SWITCH}=native "
                            "(results then match other machines of the same kind only)")
    if cpu_flags() and isa() == "other":
        raise NumericsError(f"this CPU ({cpu_model()}) has no AVX2/FMA, which the pinned kernels need; set "
                            f"{SWITCH}=native")
    late = [name for name in _LIBRARIES if name in sys.modules]
    unset = {k: v for k, v in PINNED_ENV.items() if os.environ.get(k) != v}
    if late and unset:
        raise NumericsError(f"{', '.join(late)} loaded before lfdt.numerics could pin "
                            f"{', '.join(sorted(unset))}: import lfdt (or lfdt.numerics) before them")
    os.environ.update(PINNED_ENV)


def describe() -> dict[str, str]:
    """What the numbers of this process depend on: mode, CPU model and ISA, and the pinned variables."""
    out = {"numerics": mode(), "cpu_model": cpu_model(), "cpu_isa": isa(), "machine": platform.machine()}
    if pinned():
        out.update({f"env.{k}": os.environ.get(k, "") for k in PINNED_ENV})
    return out


try:
    pin()
except InputError as err:
    # a wrong value of the switch: every number of this process would depend on it, and no caller can do better than
    # stop. The program's entry point (lfdt.stage.main, a CLI's main) is not imported yet, so this is its one line
    # and exit code 2; SystemExit, unlike an ImportError, prints no traceback
    print(f"error: {err}", file=sys.stderr)
    raise SystemExit(2) from None
