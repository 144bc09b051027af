"""converter.isolated.die_with_parent: a child that called it does not outlive its parent."""

import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _alive(pid: int) -> bool:
    """Whether pid runs (a zombie waiting for its reaper counts as gone)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def test_a_killed_parent_takes_its_child_with_it(tmp_path):
    if not sys.platform.startswith("linux"):
        pytest.skip("the parent-death signal is Linux's")
    pid_file = tmp_path / "pid"
    child = textwrap.dedent(f"""
        import os, sys, time
        sys.path.insert(0, {str(ROOT)!r})
        from converter.isolated import die_with_parent
        die_with_parent(int(sys.argv[1]))
        open({str(pid_file)!r}, "w").write(str(os.getpid()))
        time.sleep(30)
    """)
    script = textwrap.dedent(f"""
        import os, subprocess, sys, time
        subprocess.Popen([sys.executable, "-c", {child!r}, str(os.getpid())])
        time.sleep(60)
    """)
    parent = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT)
    try:
        deadline = time.monotonic() + 60
        while not pid_file.exists() or not pid_file.read_text():
            assert parent.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        pid = int(pid_file.read_text())
        assert _alive(pid)
        parent.kill()
        parent.wait()
        deadline = time.monotonic() + 10
        while _alive(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(pid)
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()


def test_a_child_whose_parent_is_already_gone_exits_at_once():
    code = ("import os, sys; sys.path.insert(0, sys.argv[1]); from converter.isolated import die_with_parent; "
            "die_with_parent(1 if sys.argv[2] == 'other' else os.getppid()); print('ran on')")
    gone = subprocess.run([sys.executable, "-c", code, str(ROOT), "other"], capture_output=True, text=True)
    assert gone.returncode == 1 and gone.stdout == ""
    here = subprocess.run([sys.executable, "-c", code, str(ROOT), "mine"], capture_output=True, text=True)
    assert here.returncode == 0 and here.stdout.strip() == "ran on"
