"""What a measured piece of work cost, counting the processes it forks (the occlusion pass ran in a forked child
until 2026-12-06; a child's share would be missing from this process's own clock and ru_maxrss).

    c = usage.cpu(); work(); seconds = usage.cpu() - c      # user+sys of this process and its waited-for children
    usage.peak_mb()                                          # the larger of this process's and any child's peak RSS
    usage.own_peak_mb()                                      # this process's (its VmHWM: see peak_mb)
    with usage.TreePss(pid) as tree: ...; tree.peak_mb      # sampled peak of the sum of a process tree's PSS
    out, mb = usage.run_measured(cmd)                       # subprocess.run, and that peak of its tree

A forked child shares its parent's pages until either writes them, so the two peaks RSS neither add up (the shared
pages would count twice) nor does the larger bound the machine's use (the child's own pages come on top of the
parent's). The sum of the tree's proportional set sizes (PSS: each shared page split between its sharers) is what
the machine holds; TreePss samples it from outside the measured processes, every 20 ms, so it misses spikes
shorter than that. Reading a process's PSS walks its whole page table under its memory-map lock, so run_measured
samples only while the process has children: a lone process's peak is its own high-water mark, exact and free. (Sampling
throughout took the bench parent a third of a core on a 2-core machine, against a 2-9 GB conversion whose page
faults waited on that lock.)
"""

from __future__ import annotations

import resource
import subprocess
import threading
from pathlib import Path


def cpu() -> float:
    """User + sys seconds of this process (all threads) and of its children that have been waited for."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def peak_mb() -> float:
    """The larger of this process's peak RSS and its largest waited-for child's, in MiB.

    This process's own is its memory map's high-water mark (VmHWM), not ru_maxrss: Linux carries the RSS of the
    process that spawned this one into ru_maxrss at exec (a child of a 425 MB parent reported 425 MB with a high
    water of 11 MB), so a measured child of a bench parent grown large would report the parent's size."""
    return max(own_peak_mb(), resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)


def own_peak_mb() -> float:
    """This process's peak RSS in MiB: its VmHWM (peak_mb), ru_maxrss where /proc does not tell."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except (OSError, ValueError, IndexError):
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _tree(pid: int) -> list[int]:
    """pid and its descendants now alive."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        try:
            for task in Path(f"/proc/{p}/task").iterdir():
                todo += [int(c) for c in (task / "children").read_text().split()]
        except OSError:  # gone meanwhile
            continue
    return out


def tree_pss_kb(pid: int) -> int:
    """Sum of the PSS (kB) of pid and its descendants; 0 where /proc has no smaps_rollup."""
    total = 0
    for p in _tree(pid):
        try:
            for line in Path(f"/proc/{p}/smaps_rollup").read_text().splitlines():
                if line.startswith("Pss:"):
                    total += int(line.split()[1])
                    break
        except (OSError, ValueError):
            continue
    return total


class TreePss:
    """A sampler thread: the peak over time of tree_pss_kb(pid), as peak_mb, while the with-block runs; with
    forked_only, only at the times pid has descendants (the caller takes the lone process's ru_maxrss)."""

    def __init__(self, pid: int, interval: float = 0.02, forked_only: bool = False) -> None:
        self.pid, self.interval, self.forked_only, self.peak_kb = pid, interval, forked_only, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def _sample(self) -> None:
        while not self._stop.is_set():
            if not self.forked_only or len(_tree(self.pid)) > 1:
                self.peak_kb = max(self.peak_kb, tree_pss_kb(self.pid))
            self._stop.wait(self.interval)

    def __enter__(self) -> TreePss:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    @property
    def peak_mb(self) -> float:
        """The peak sampled, in MiB."""
        return self.peak_kb / 1024


def run_measured(cmd: list[str], **kwargs) -> tuple[subprocess.CompletedProcess, float]:
    """subprocess.run(cmd, capture_output=True, text=True, **kwargs), raising on a non-zero exit, while sampling
    the PSS of its process tree whenever the process has children: (the completed process, peak MiB of the sum;
    the caller adds the process's own peak RSS, which cmd reports)."""
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs) as proc:
        with TreePss(proc.pid, forked_only=True) as tree:
            out, err = proc.communicate()
    if proc.returncode:
        raise subprocess.CalledProcessError(proc.returncode, cmd, out, err)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err), tree.peak_mb
