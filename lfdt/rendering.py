"""Whether MuJoCo can render here, checked before the work whose videos need it.

MuJoCo picks its OpenGL backend from ``MUJOCO_GL`` (``lfdt`` sets ``egl`` when it is unset). A value exported for
another purpose (``glfw`` for MuJoCo's viewer, on a machine without a display; ``osmesa`` without its library; a typo)
fails only at the first frame of the first video: in the full pipeline after hours of training, as a traceback. The
check draws one small frame in a child process, so that no OpenGL state is left in a process that forks workers.
"""

from __future__ import annotations

import os
import subprocess
import sys

from lfdt.errors import InputError

PROBE = """
import mujoco
model = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size="0.1"/></worldbody></mujoco>')
with mujoco.Renderer(model, 16, 16) as r:
    r.update_scene(mujoco.MjData(model))
    r.render()
"""
"""What the child runs: one frame of a one-sphere model."""

TIMEOUT_S = 60
"""The child's time limit (importing MuJoCo and making a context take 1-3 s)."""


def check_rendering(needed_by: str) -> None:
    """An :class:`~lfdt.errors.InputError` naming ``MUJOCO_GL`` when MuJoCo cannot draw a frame in this environment;
    ``needed_by`` says what would render (a params key and its value), so that the line says how to go on."""
    backend = os.environ.get("MUJOCO_GL", "")
    try:
        proc = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        reason = f"drawing one frame took more than {TIMEOUT_S} s"
    else:
        if proc.returncode == 0:
            return
        lines = [line.strip() for line in proc.stderr.splitlines() if line.strip()]
        reason = lines[-1][:240] if lines else f"exit code {proc.returncode}"
    raise InputError(f"MUJOCO_GL={backend!r}: MuJoCo cannot render here ({reason}); {needed_by} writes videos: run "
                     f"with MUJOCO_GL=egl (osmesa where EGL is missing), or set it to 0")


def check_videos(count: int, key: str) -> None:
    """:func:`check_rendering` when params.yaml's ``key`` asks for ``count`` > 0 videos."""
    if count:
        check_rendering(f"params.yaml {key} = {count}")
