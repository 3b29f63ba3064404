"""LfDT: learning dual-arm manipulation from demonstrations translated from a human and a robotic arm."""

import os

# MuJoCo picks its GL backend at import time; headless machines need EGL for offscreen rendering.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"
