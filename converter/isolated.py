"""Child processes that do not outlive their parent.

The web app's workers and work horses call die_with_parent, so that a server or worker killed mid-job leaves no
process running on for nobody. (This module also ran the occlusion pass in a forked child while that pass used
Mesa's EGL, whose driver memory then left with the child; the pass no longer uses GL: converter.raster.)
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(parent_pid: int | None = None) -> None:
    """Ask Linux to SIGKILL this process when its parent dies; exit now if the parent is already gone."""
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the caller's own checks must do
            pass
    if parent_pid is not None and os.getppid() != parent_pid:
        os._exit(1)
