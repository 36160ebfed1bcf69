"""Giving the memory a stage has freed back to the system between its phases.

A stage's large arrays are freed phase by phase, but the C allocator keeps
the freed pages of its heap for later allocations; blocks of mixed sizes
leave them fragmented, so the process's resident memory stays at its
largest even where the arrays alive are far fewer. ``malloc_trim`` (glibc)
returns the free pages. Elsewhere (macOS, musl) :func:`release` does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["release"]

_trim = None


def release() -> None:
    """Return the allocator's free heap pages to the system (glibc's ``malloc_trim(0)``; else nothing).

    Notes
    -----
    Measured on the fields stage of the moving tube (13,104 points x 300
    times): at the start of the strain's noise probes the process held
    3.08 GB resident for 2.15 GB of live arrays, 2.62 GB after the trim.
    """
    global _trim
    if _trim is None:
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            _trim = libc.malloc_trim
        except (OSError, AttributeError):
            _trim = False
    if _trim:
        _trim(0)
