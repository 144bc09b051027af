"""bench/usage.py: the bench's tree-memory sampler counts a forked child and leaves a lone process alone."""

import subprocess
import sys
import textwrap
import time
from pathlib import Path

from bench import usage

# The measured process: 60 MB of its own, then a forked child that writes 80 MB more while both live.
FORKS = textwrap.dedent("""
    import os, time
    own = bytearray(60 << 20)
    time.sleep(0.3)
    pid = os.fork()
    if pid == 0:
        extra = bytearray(80 << 20)
        time.sleep(0.5)
        os._exit(0)
    os.waitpid(pid, 0)
""")
ALONE = "import time; own = bytearray(60 << 20); time.sleep(0.8)"
WAIT_S = 10.0  # the longest a loaded machine may take to start a Python and touch 60 MB


def test_tree_sampler_counts_a_forked_child_on_top_of_its_parent():
    _, peak = usage.run_measured([sys.executable, "-c", FORKS])
    assert peak > 60 + 80  # the child's own pages on top of the parent's (shared ones once)


def test_tree_sampler_reads_nothing_while_the_process_is_alone():
    # A lone process's peak is its ru_maxrss: run_measured does not walk its page table every 20 ms meanwhile ...
    _, peak = usage.run_measured([sys.executable, "-c", ALONE])
    assert peak == 0
    # ... where a sampler asked to sample throughout sees its 60 MB.
    with subprocess.Popen([sys.executable, "-c", ALONE]) as proc:
        with usage.TreePss(proc.pid) as tree:
            deadline = time.monotonic() + WAIT_S
            while tree.peak_mb <= 60 and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.02)
        proc.wait()
    assert tree.peak_mb > 60


def test_a_child_s_peak_is_its_own_not_the_size_of_the_process_that_spawned_it():
    # Linux carries the spawning process's RSS into the child's ru_maxrss at exec: a bench parent grown to 200 MB
    # would make every measured child report at least 200 MB. usage.peak_mb reads the child's own high water.
    big = b"\x01" * (200 << 20)  # every page written
    code = "from bench import usage; import resource; print(usage.peak_mb(), resource.getrusage(0).ru_maxrss / 1024)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=str(Path(usage.__file__).resolve().parents[1]))
    own, maxrss = map(float, out.stdout.split())
    assert len(big) and maxrss > 200 and own < 100
