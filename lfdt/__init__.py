"""LfDT: learning dual-arm manipulation from demonstrations translated from a human and a robotic arm."""

import os

# first, before anything can load numpy, torch or mujoco: one numeric code path on every x86-64 CPU
from lfdt import numerics  # noqa: F401  (its import pins; see lfdt/numerics.py)

# MuJoCo picks its GL backend at import time; headless machines need EGL for offscreen rendering.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"
