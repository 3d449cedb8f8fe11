"""A node process started by ``ema launch`` ends when the launcher does, however the launcher ends.

``ema launch`` stops its nodes itself on SIGINT, SIGTERM and SIGHUP (the driver first: it closes the bag).
SIGKILL leaves it no say, so each node asks the kernel for a parent-death signal (Linux ``prctl
PR_SET_PDEATHSIG``): when the launcher's process ends, every node gets SIGTERM and stops as on any SIGTERM,
its bag closed. The launcher names itself in ``EMA_PARENT_PID``; a node whose parent is already gone by the
time it asks (the launcher died while it started) stops at once.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal

PARENT_ENV = "EMA_PARENT_PID"
PR_SET_PDEATHSIG = 1


def follow_parent(sig: int = signal.SIGTERM) -> bool:
    """Get ``sig`` when the parent process ends, if ``EMA_PARENT_PID`` names it; True when armed.

    Parameters
    ----------
    sig : int
        The signal to get.

    Returns
    -------
    bool
        The kernel will send it (``PR_SET_PDEATHSIG`` armed).
    """
    wanted = os.environ.get(PARENT_ENV)
    if not wanted:
        return False
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
        return False
    if str(os.getppid()) != wanted:  # the launcher ended before the signal was armed
        os.kill(os.getpid(), sig)
    return True
