"""Free memory handed back to the system between the conversion's phases.

numpy's arrays below glibc's (dynamic, up to 32 MB) mmap threshold live in the C heap. When a phase frees its
temporaries the heap keeps their pages, fragmented between what is still alive, so a conversion's resident
memory ratchets up phase after phase even where what is alive shrinks. ``malloc_trim`` gives the free pages
back (it also releases pages in the middle of the heap, with madvise). Elsewhere than glibc it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _trim():
    """glibc's malloc_trim, or None."""
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


def give_back() -> None:
    """Return the C heap's free pages to the system (a few ms; glibc only)."""
    trim = _trim()
    if trim is not None:
        trim(0)
