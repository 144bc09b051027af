"""The occlusion pass runs in a forked child (converter.isolated): same result, progress and errors as in this
process, and neither a killed child nor a killed parent leaves a job hanging or a process running on."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import SAMPLE
from converter import egl, isolated
from converter.errors import RenderError

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def forking(monkeypatch):
    """run() forks even if this test process has initialised EGL: the work in these tests does not touch it."""
    monkeypatch.setattr(egl, "_used", False)
    assert isolated.can_fork()


def _pid(progress=None) -> int:
    return os.getpid()


def _gone(pid: int) -> bool:
    """pid has exited and been reaped (no zombie left behind)."""
    return not Path(f"/proc/{pid}").exists()


def _array(n, progress=None) -> np.ndarray:
    for k in range(n):
        progress((k + 1) / n)
    return np.arange(n) * 2


class NeedsTwo(Exception):
    def __init__(self, a, b):  # pickles, but does not unpickle (its args are one string)
        super().__init__(f"{a} {b}")


def _raise(kind, pid_file, progress=None):
    Path(pid_file).write_text(str(os.getpid()))
    if kind == "value":
        raise ValueError("bad frame 7")
    if kind == "local":
        class Local(Exception):  # a class defined in a function does not pickle
            pass

        raise Local("a local error")
    raise NeedsTwo("two", "args")


def _kill_self(pid_file, progress=None):
    Path(pid_file).write_text(str(os.getpid()))
    os.kill(os.getpid(), signal.SIGKILL)


def _terms_itself(progress=None) -> int:
    os.kill(os.getpid(), signal.SIGTERM)
    os.kill(os.getpid(), signal.SIGINT)
    return 5


def _slow(pid_file, progress=None):
    Path(pid_file).write_text(str(os.getpid()))
    for k in range(600):
        time.sleep(0.05)
        if progress:
            progress(k / 600)


def test_the_work_runs_in_a_child_and_its_result_and_progress_come_back(forking):
    child = isolated.run(_pid)
    assert child != os.getpid() and _gone(child)
    seen = []
    got = isolated.run(_array, 5, progress=seen.append)
    assert np.array_equal(got, np.arange(5) * 2)
    assert seen == [0.2, 0.4, 0.6, 0.8, 1.0]


def test_after_egl_is_initialised_here_the_work_runs_here(monkeypatch):
    monkeypatch.setattr(egl, "_used", True)
    assert not isolated.can_fork()
    assert isolated.run(_pid) == os.getpid()


def test_an_error_in_the_child_is_raised_here_with_its_type(forking, tmp_path):
    pid = tmp_path / "pid"
    with pytest.raises(ValueError, match="bad frame 7"):
        isolated.run(_raise, "value", str(pid))
    assert _gone(int(pid.read_text()))
    with pytest.raises(RenderError, match="Local: a local error"):
        isolated.run(_raise, "local", str(pid))
    with pytest.raises(RenderError, match="NeedsTwo: two args"):
        isolated.run(_raise, "two", str(pid))
    assert _gone(int(pid.read_text()))


def test_a_child_killed_without_a_word_raises_render_error(forking, tmp_path):
    pid = tmp_path / "pid"
    with pytest.raises(RenderError, match="the occlusion pass stopped: its process was killed by SIGKILL.*memory"):
        isolated.run(_kill_self, str(pid), what="the occlusion pass")
    assert _gone(int(pid.read_text()))


def test_the_signals_that_stop_a_server_or_a_terminal_job_reach_the_parent_not_the_child(forking):
    # Ctrl-C and a stopped server's SIGTERM go to the whole process group: the parent decides (a server leaves
    # its running job to be re-queued); a child dying first would fail the job.
    assert isolated.run(_terms_itself) == 5


def test_when_the_caller_stops_the_child_is_killed(forking, tmp_path):
    class Cancelled(Exception):
        pass

    def cancel(f):
        raise Cancelled

    pid_file = tmp_path / "pid"
    with pytest.raises(Cancelled):
        isolated.run(_slow, str(pid_file), progress=cancel)
    assert _gone(int(pid_file.read_text()))


def test_a_killed_parent_takes_its_child_with_it(tmp_path):
    if not sys.platform.startswith("linux"):
        pytest.skip("the parent-death signal is Linux's")
    pid_file = tmp_path / "pid"
    script = textwrap.dedent(f"""
        import os, sys, time
        sys.path.insert(0, {str(ROOT)!r})
        from converter import isolated

        def slow(progress=None):
            open({str(pid_file)!r}, "w").write(str(os.getpid()))
            time.sleep(30)

        isolated.run(slow)
    """)
    parent = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT)
    try:
        deadline = time.monotonic() + 60
        while not pid_file.exists() or not pid_file.read_text():
            assert parent.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        child = int(pid_file.read_text())
        parent.kill()
        parent.wait()
        deadline = time.monotonic() + 10
        while _alive(child) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(child)
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()


def _alive(pid: int) -> bool:
    """Whether pid runs (a zombie waiting for its reaper counts as gone)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def test_the_forked_occlusion_pass_keeps_what_the_pass_here_keeps():
    # In a fresh interpreter, where no EGL display exists yet: the first pass forks (and leaves EGL unused here),
    # the second runs the same work in this process.
    script = textwrap.dedent(f"""
        import json, os, sys
        os.environ["PYOPENGL_PLATFORM"] = "egl"
        sys.path.insert(0, {str(ROOT)!r})
        import numpy as np
        from converter import egl, idpass, isolated
        from converter.extract import cull, fit_camera
        from converter.formats import load
        anim = load({str(SAMPLE)!r})
        cam = fit_camera(anim, 256)
        xy, z, w = cam.project(anim.frames)
        vis = cull(xy, z, w, anim.faces, cam.width, cam.height)
        assert isolated.can_fork()
        seen = []
        forked = idpass.ever_seen(anim.frames, anim.faces, cam, vis, progress=seen.append)
        forked_left_egl_unused = not egl.used()
        here = idpass._ever_seen(anim.frames, anim.faces, cam, vis)
        print(json.dumps({{"forked": forked.tolist(), "here": here.tolist(), "unused": forked_left_egl_unused,
                          "progress": seen, "frames": anim.n_frames, "after": isolated.can_fork()}}))
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["unused"] and not r["after"]
    assert r["forked"] == r["here"] and 0 < sum(r["here"]) < len(r["here"])
    assert len(r["progress"]) == r["frames"] and r["progress"][-1] == 1.0


def test_a_fork_while_another_thread_holds_numbas_compiler_lock_does_not_leave_the_child_waiting():
    # A sibling job's thread compiling (numba's global lock held) when the pass forks: the child, compiling or
    # loading its own kernels, would wait for a lock no thread of its own will ever release.
    script = textwrap.dedent(f"""
        import sys, threading, time
        sys.path.insert(0, {str(ROOT)!r})
        import numba
        from numba.core.compiler_lock import global_compiler_lock
        from converter import isolated

        held = threading.Event()

        def compiling():
            with global_compiler_lock:
                held.set()
                time.sleep(1.0)

        def work(progress=None):
            return numba.njit(lambda x: x + 1)(41)

        threading.Thread(target=compiling).start()
        held.wait()
        print(isolated.run(work))
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["42"]


def test_a_child_reaped_elsewhere_still_gives_its_result(forking):
    # SIGCHLD ignored (as some process supervisors leave it): the kernel reaps the child, waitpid finds none.
    old = signal.signal(signal.SIGCHLD, signal.SIG_IGN)
    try:
        assert np.array_equal(isolated.run(_array, 3, progress=lambda f: None), [0, 2, 4])
        with pytest.raises(RenderError, match="ended without a result"):
            isolated.run(_kill_self, os.devnull)
    finally:
        signal.signal(signal.SIGCHLD, old)
