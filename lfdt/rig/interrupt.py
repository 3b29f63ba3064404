"""Ctrl-C around anything that can be stopped and closed (an arm, a rig): stop it, close it, then let the interrupt
propagate. Below both the robots (:mod:`lfdt.robot.arm`) and the hardware-free rig (:mod:`lfdt.rig.base`)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, Protocol


class Stoppable(Protocol):
    """What :func:`stop_on_interrupt` needs: an arm or a rig."""

    def stop(self) -> None: ...

    def close(self) -> None: ...


def _restore_sigint(previous: Any) -> None:
    # None means a handler installed outside Python; the default is the closest we can put back
    signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)


def emergency_stop(arm: Stoppable) -> None:
    """Stop then close ``arm``, closing even when stop fails; a Ctrl-C in between is ignored."""
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if in_main else None
    try:
        try:
            arm.stop()
        finally:
            arm.close()
    finally:
        if in_main:
            _restore_sigint(previous)


@contextmanager
def stop_on_interrupt(arm: Stoppable) -> Iterator[Stoppable]:
    """Within the block, Ctrl-C (SIGINT) stops and closes ``arm``, then KeyboardInterrupt propagates.

    The handler itself only raises: stopping from inside it could deadlock on the lock pymycobot holds while a
    command is in flight, so the stop runs here once the stack has unwound. Outside the main thread (where Python
    delivers no signals) no handler is installed. On a normal exit the arm is left open.
    """
    def on_sigint(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    in_main = threading.current_thread() is threading.main_thread()
    # installed explicitly because the process may have inherited SIGINT as ignored (started with nohup or &)
    previous = signal.signal(signal.SIGINT, on_sigint) if in_main else None
    try:
        yield arm
    except KeyboardInterrupt:
        emergency_stop(arm)
        raise
    finally:
        if in_main:
            _restore_sigint(previous)
