"""bench/usage.py: the bench's tree-memory sampler counts a forked child and leaves a lone process alone."""

import subprocess
import sys
import textwrap
import time

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
