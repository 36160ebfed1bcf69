"""Safe replacement of irdic's outputs: temporaries, writer lock and the swap.

Every output (a zarr store or a folder of files) is written to a hidden
sibling directory ``.<name>.tmp-<pid>-<random>-<host>`` and moved into place
only when it is complete (:func:`atomic_directory`). A job that dies half-way
leaves nothing under the final name; its temporary is removed by the next
writer of the same output once its process is known to be gone.

Replacing an output never exposes a mix: the old directory is exchanged with
the new one in one step (two renames where the system cannot) and deleted
only afterwards. Jobs writing the same output take turns through a lock file
``.<name>.lock`` next to it, which exists only while a writer holds or waits
for it: the last writer removes it. Only irdic's own outputs are ever replaced: an
irdic zarr store (it carries ``irdic_stage`` or :data:`COMPLETE_ATTR`), a
folder carrying :data:`OUTPUT_MARK`, or an empty folder; anything else is
refused.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import glob
import json
import os
import re
import shutil
import socket
import sys
import time
import uuid
from pathlib import Path
from typing import Iterator

from .errors import DataError, OutputError

__all__ = [
    "atomic_directory",
    "zarr_group_attrs",
    "OUTPUT_MARK",
    "COMPLETE_ATTR",
    "LOCK_TIMEOUT_S",
    "STALE_AGE_S",
]

#: group attribute of a finished irdic zarr store, written last (see :mod:`irdic.store`);
#: a store carrying it is irdic's and may be replaced
COMPLETE_ATTR = "irdic_complete"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


#: a temporary or set-aside copy of another host's job is removed only when older than this (s):
#: that job may still be running on a shared file system, and its process cannot be asked about
STALE_AGE_S = 7 * 24 * 3600.0
#: how long a writer waits for another job writing the same output before giving up (s)
LOCK_TIMEOUT_S = 600.0
#: file that marks a folder (not a zarr store) as written by irdic, so that it may be replaced
OUTPUT_MARK = ".irdic-output"
#: files other tools drop into output folders that do not make a folder the user's
_HARMLESS = {".snakemake_timestamp"}


def _host() -> str:
    # the host is part of temporaries' names: '/' would make a path, and '.' keeps names readable
    return re.sub(r"[^A-Za-z0-9_.-]", "_", socket.gethostname() or "unknown")


def _sibling(final: Path, kind: str) -> Path:
    return final.with_name(f".{final.name}.{kind}-{os.getpid()}-{uuid.uuid4().hex[:8]}-{_host()}")


def _owner(tmp: Path, final: Path, kind: str) -> tuple[int | None, str | None]:
    """(pid, host) encoded in a temporary's name; host is None for names of older irdic versions."""
    rest = tmp.name[len(f".{final.name}.{kind}-"):]
    parts = rest.split("-", 2)
    try:
        pid = int(parts[0])
    except ValueError:
        return None, None
    return pid, (parts[2] if len(parts) == 3 else None)


def _remove_stale_siblings(final: Path) -> None:
    """Remove temporaries of ``final`` left by dead jobs.

    A temporary of this host is removed when its process is gone; one of
    another host (or of an older irdic, whose names carry no host) only when
    it is older than :data:`STALE_AGE_S`, because ``os.kill`` cannot see
    processes on other nodes of a cluster sharing the file system.
    """
    now = time.time()
    for kind in ("tmp", "old"):
        for tmp in final.parent.glob(f".{glob.escape(final.name)}.{kind}-*"):
            pid, host = _owner(tmp, final, kind)
            if pid is None:
                continue
            if host == _host():
                stale = not _pid_alive(pid)
            else:
                try:
                    stale = now - tmp.lstat().st_mtime > STALE_AGE_S
                except OSError:
                    continue
            if stale:
                _remove(tmp)


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            p.unlink()


def zarr_group_attrs(path: Path) -> dict | None:
    """Attributes of the zarr v3 group at ``path``, or None when it is not one."""
    try:
        with open(path / "zarr.json", encoding="utf-8") as fh:
            meta = json.load(fh)
    except (OSError, ValueError):
        return None
    if not isinstance(meta, dict) or meta.get("node_type") != "group":
        return None
    attrs = meta.get("attributes")
    return attrs if isinstance(attrs, dict) else {}


def _replaceable(final: Path) -> bool:
    """True when ``final`` may be replaced: absent, empty, an irdic store or an irdic-marked folder."""
    if not os.path.lexists(final):
        return True
    if final.is_symlink() or not final.is_dir():
        return False
    attrs = zarr_group_attrs(final)
    if attrs is not None and ("irdic_stage" in attrs or COMPLETE_ATTR in attrs):
        return True
    if (final / OUTPUT_MARK).is_file():
        return True
    return all(p.name in _HARMLESS for p in final.iterdir())


def _check_replaceable(final: Path) -> None:
    if not _replaceable(final):
        what = ("a symbolic link" if final.is_symlink() else "a folder" if final.is_dir() else "a file")
        raise DataError(
            f"{final}: output path exists and is {what} that irdic did not write; irdic replaces only "
            "its own stores and output folders. Choose another output path, or move it away yourself"
        )


_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap ``a`` and ``b`` in one step (Linux ``renameat2``); False where unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    rc = fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTSUP):
        return False  # file system without exchange (some network ones): fall back to two renames
    raise OSError(err, os.strerror(err), os.fspath(b))


def _swap_in(tmp: Path, final: Path) -> None:
    """Put ``tmp`` at ``final`` so that a reader sees the old or the new directory, never a mix.

    The old directory is moved aside (exchanged in one step where the
    system can) and only then deleted; readers of the old one that are
    still loading chunks then meet missing files, which :func:`irdic.store.open_store`
    reports, instead of the new store's chunks.
    """
    if not os.path.lexists(final):
        os.replace(tmp, final)
        return
    if _exchange(tmp, final):
        _remove(tmp)  # now holds the old directory
        return
    aside = _sibling(final, "old")
    os.replace(final, aside)
    os.replace(tmp, final)
    _remove(aside)


def _lock_path(final: Path) -> Path:
    return final.with_name(f".{final.name}.lock")


def _try_lock(path: Path) -> int | None:
    """An open descriptor holding ``path``'s exclusive lock, or None when another writer holds it.

    A lock file is removed by its holder on release (:func:`_unlock`), so a
    writer that waited on the old file may find it gone or replaced once it
    gets the lock: the lock counts only when ``path`` still names the file
    locked, otherwise the caller tries again.
    """
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    try:
        now = os.stat(path)
    except FileNotFoundError:
        now = None
    held = os.fstat(fd)
    if now is None or (now.st_ino, now.st_dev) != (held.st_ino, held.st_dev):
        os.close(fd)  # the holder before us removed it: lock the file now at the path
        return _try_lock(path)
    return fd


def _unlock(path: Path, fd: int) -> None:
    """Remove the lock file while still holding it, then release: no ``.*.lock`` stays behind."""
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)
    os.close(fd)


@contextlib.contextmanager
def _writer_lock(final: Path, timeout: float | None) -> Iterator[None]:
    """Hold the lock of ``final`` (``.<name>.lock`` beside it) so that two jobs writing it take turns.

    The lock file exists only while a writer holds it or waits for it.
    """
    timeout = LOCK_TIMEOUT_S if timeout is None else timeout
    path = _lock_path(final)
    deadline = time.monotonic() + timeout
    while (fd := _try_lock(path)) is None:
        if time.monotonic() >= deadline:
            others = sorted(p.name for p in final.parent.glob(f".{glob.escape(final.name)}.tmp-*"))
            who = f" (its temporary: {others[0]})" if others else ""
            raise DataError(
                f"{final}: another job has been writing this output for over {timeout:g} s{who}; "
                "wait for it to finish, or stop it, then run again"
            )
        time.sleep(min(0.05, max(0.0, deadline - time.monotonic())))
    try:
        yield
    finally:
        _unlock(path, fd)


def write_failure(exc: BaseException, tmp: Path, final: Path) -> OutputError | None:
    """The :class:`OutputError` naming ``final`` for an OSError of writing ``tmp`` (disk full, quota), else None.

    An OSError that names a file outside the output (an input being read)
    keeps its own message.
    """
    if not isinstance(exc, OSError):
        return None
    name = exc.filename
    if name is not None:
        p = Path(os.fsdecode(name)) if isinstance(name, (str, bytes, os.PathLike)) else None
        if p is None or not (p in (tmp, final) or tmp in p.parents or final in p.parents):
            return None
    kept = f"the previous {final.name} is kept" if final.exists() else f"nothing was written to {final}"
    return OutputError(f"{final}: writing failed ({exc.strerror or exc}); {kept}")


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike, *, lock_timeout: float | None = None) -> Iterator[Path]:
    """Yield a temporary sibling of ``path``; move it to ``path`` on success.

    On any exception the temporary directory is removed and ``path`` is left
    as it was before (an older complete result stays; nothing half-written
    appears). An existing ``path`` is replaced only when irdic wrote it (an
    irdic zarr store, or a folder carrying :data:`OUTPUT_MARK`) or when it is
    an empty folder; anything else is refused before any work is done.
    Jobs writing the same ``path`` take turns (a lock file next to it).

    Parameters
    ----------
    path : path-like
        Final location of the directory (for example ``results/x/ir.zarr``).
    lock_timeout : float, optional
        Seconds to wait for another job writing ``path`` (default
        :data:`LOCK_TIMEOUT_S`).

    Raises
    ------
    DataError
        ``path`` exists and was not written by irdic, or another job holds
        it for longer than ``lock_timeout``.
    """
    final = Path(path)
    _check_replaceable(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    with _writer_lock(final, lock_timeout):
        _remove_stale_siblings(final)
        tmp = _sibling(final, "tmp")
        try:
            yield tmp
            if tmp.is_dir() and not (tmp / "zarr.json").exists():
                # a plain output folder: mark it as irdic's so that a later run may replace it
                (tmp / OUTPUT_MARK).write_text("written by irdic; the whole folder is replaced on the next run\n",
                                              encoding="utf-8")
            _check_replaceable(final)  # something may have appeared while we were computing
            _swap_in(tmp, final)
        except BaseException as exc:
            shutil.rmtree(tmp, ignore_errors=True)
            failure = write_failure(exc, tmp, final)
            if failure is not None:
                raise failure from exc
            raise
