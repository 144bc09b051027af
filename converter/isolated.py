"""Work run in a forked child process, so that what it maps leaves with the child.

The occlusion pass's EGL context loads Mesa's driver and its LLVM (llvmpipe): 70-135 MB of resident memory that
stays mapped after the context is destroyed, for the rest of the conversion (whose peak comes later) and for
the rest of a web worker's life. In a child forked for the pass the parent's pages are shared, not copied; the
child sends back its small result and its progress, and everything it mapped goes when it exits. It dies with
its parent (on Linux, by the parent-death signal), so a worker killed mid-job leaves nothing running.

A fork is used only where it is safe for this work: on a platform with fork, and only while no EGL display has
been initialised in this process (a driver's state does not survive fork; after a prerender the pass runs
here, as it did before). The child only computes and writes to its pipe: it takes no lock another thread of
the parent could hold at the fork (the job store's it never touches; numba's is held across the fork by the
forking thread, the others are reset by fork handlers), and leaves with os._exit.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import pickle
import signal
import sys
import warnings
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from typing import Any

from converter import egl
from converter.errors import RenderError

Progress = Callable[[float], None]
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def can_fork() -> bool:
    """Whether run() forks here: the platform has fork and this process has not initialised an EGL display."""
    return hasattr(os, "fork") and not egl.used()


def run(fn: Callable[..., Any], *args: Any, progress: Progress | None = None, what: str = "the work") -> Any:
    """fn(*args, progress=...) in a forked child when can_fork(), else here; its result, progress and errors
    as if called here. The child is killed when this side stops (a cancelled job, Ctrl-C); a child that dies
    without a word (killed, out of memory) raises RenderError naming what it was doing."""
    if not can_fork():
        return fn(*args, progress=progress)
    # os.fork, not multiprocessing.Process: a web worker is a daemonic process, which multiprocessing forbids
    # to have children, and the child must run no exit handlers of the parent's (os._exit).
    receive, send = multiprocessing.Pipe(duplex=False)
    parent = os.getpid()
    with warnings.catch_warnings(), _fork_locks():  # Python 3.12+ warns on fork with threads: see _fork_locks
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # the child: whatever happens, it leaves here
        code = 1
        try:
            receive.close()
            _child(send, parent, fn, args, progress is not None)
            code = 0
        finally:
            os._exit(code)
    send.close()
    reaped = False
    try:
        while True:
            try:
                kind, value = receive.recv()
            except EOFError:
                break
            if kind == "progress":
                if progress:
                    progress(value)
                continue
            reaped, _ = True, _reap(pid)
            if kind == "error":
                raise value
            return value
        reaped, status = True, _reap(pid)
        raise RenderError(f"{what} stopped: {_death(status)}; the machine may be short of memory.")
    finally:
        receive.close()
        if not reaped:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            _reap(pid)


def _reap(pid: int) -> int | None:
    """Wait for child pid: its wait status, None if something else reaped it (SIGCHLD ignored, say)."""
    try:
        return os.waitpid(pid, 0)[1]
    except ChildProcessError:
        return None


def _fork_locks() -> AbstractContextManager:
    """The locks the child may take that no fork handler resets, held by this thread across the fork so that no
    other thread holds them then: numba's compiler lock (a child loading a compiled function from the cache while
    a sibling job's thread was compiling would wait for ever). Python resets its import lock and logging's;
    glibc and OpenBLAS reset theirs."""
    if "numba" not in sys.modules:
        return nullcontext()
    from numba.core.compiler_lock import global_compiler_lock  # noqa: PLC0415 - only where numba is loaded

    return global_compiler_lock


def _death(status: int | None) -> str:
    """How a child that sent no result ended, from its wait status (None: unknown)."""
    if status is None:
        return "its process ended without a result"
    code = os.waitstatus_to_exitcode(status)
    if code < 0:
        try:
            return f"its process was killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"its process was killed by signal {-code}"
    return f"its process exited with status {code} and no result"


def die_with_parent(parent_pid: int | None = None) -> None:
    """Ask Linux to SIGKILL this process when its parent dies; exit now if the parent is already gone."""
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the caller's own checks must do
            pass
    if parent_pid is not None and os.getppid() != parent_pid:
        os._exit(1)


def _child(send, parent: int, fn: Callable[..., Any], args: tuple, report: bool) -> None:
    """The child's side of run(): every outcome is one message, so the parent never waits on a dead pipe. Its
    life is its parent's: deaf to the signals that stop a job or a server (Ctrl-C reaches the whole process
    group; a stopped server's SIGTERM must leave its job as it was, not failed by a child that died first), and
    killed by the kernel when the parent dies, so a killed worker leaves no pass running on for nobody."""
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM, signal.SIGHUP})
    die_with_parent(parent)
    try:
        result = fn(*args, progress=(lambda f: send.send(("progress", f))) if report else None)
        message = ("result", result)
    except BaseException as exc:  # every error goes to the parent, which raises it as its own
        message = ("error", exc)
        try:
            pickle.loads(pickle.dumps(exc))
        except Exception as why:  # one that does not make the trip: its text still reaches the parent
            message = ("error", RenderError(f"{type(exc).__name__}: {exc} ({why})"))
    send.send(message)
    send.close()
