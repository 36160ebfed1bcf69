"""Logging for stage scripts and the CLI.

:func:`stage_logging` sends irdic's log records to a file (the Snakemake
``log:`` of the rule) and to stderr, and turns an :class:`~irdic.errors.IrdicError`
into one readable line in the log and a non-zero exit instead of a traceback;
it also limits BLAS and OpenMP to the threads the stage was given
(:func:`irdic.threads.stage_threads`).
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import re
import sys
import threading
import time
import warnings
from pathlib import Path
from typing import Callable, Iterator

from .errors import IrdicError
from .threads import stage_threads

__all__ = ["stage_logging", "configure", "Progress", "StageProgress", "report", "failures", "show_last",
           "exit_on_error"]

_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


def configure(log_path: str | os.PathLike | None = None, level: int = logging.INFO) -> logging.Logger:
    """Send the ``irdic`` logger to stderr and, if given, to ``log_path``."""
    logger = logging.getLogger("irdic")
    logger.setLevel(level)
    for h in list(logger.handlers):
        logger.removeHandler(h)
    fmt = logging.Formatter(_FORMAT, datefmt="%H:%M:%S")
    stream = logging.StreamHandler(sys.stderr)
    stream.setFormatter(fmt)
    logger.addHandler(stream)
    if log_path is not None:
        os.makedirs(os.path.dirname(os.path.abspath(log_path)), exist_ok=True)
        fh = logging.FileHandler(log_path, mode="w", encoding="utf-8")
        fh.setFormatter(fmt)
        logger.addHandler(fh)
    logging.captureWarnings(True)
    wlog = logging.getLogger("py.warnings")
    for h in logger.handlers:
        if h not in wlog.handlers:
            wlog.addHandler(h)
    return logger


@contextlib.contextmanager
def stage_logging(log_path: str | os.PathLike | None, stage: str, *,
                  threads: int | None = None) -> Iterator[logging.Logger]:
    """Run a stage with logging to ``log_path``; exit(1) with a clear line on an irdic error.

    ``threads``: CPU threads the stage was given (Snakemake's ``threads``);
    None: all cores.
    """
    logger = configure(log_path)
    try:
        with stage_threads(threads) as n, warnings.catch_warnings():
            logger.info("irdic %s: start (%d thread%s)", stage, n, "" if n == 1 else "s")
            warnings.simplefilter("default")
            yield logger
    except IrdicError as exc:
        line = _one_line(exc)
        logger.error("%s failed: %s", stage, line)
        raise SystemExit(f"irdic {stage} failed: {line}") from None
    logger.info("irdic %s: done", stage)


def _one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (a screen shows it alone, a log keeps it on one line)."""
    return " ".join(str(exc).split())


#: The line :func:`stage_logging` writes to a rule's log when its stage fails.
_FAILED = re.compile(r" ERROR +irdic: (?P<stage>\S+) failed: (?P<message>.*)$")


def failures(log_dir: str | os.PathLike, *, since: float) -> list[str]:
    """The one-line messages of the stages that failed, from the rule logs under ``log_dir``.

    Parameters
    ----------
    log_dir : path
        The results folder's ``logs`` (each rule logs there, :func:`stage_logging`).
    since : float
        Epoch seconds; logs last written before (an earlier run's) are ignored.

    Returns
    -------
    list of str
        ``irdic <stage> failed: <message>``, one per failed stage, in the order of the log paths.
    """
    out = []
    root = Path(log_dir)
    if not root.is_dir():
        return out
    for path in sorted(root.rglob("*.log")):
        try:
            if path.stat().st_mtime < since:
                continue
            lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
        except OSError:
            continue
        for ln in reversed(lines):
            m = _FAILED.search(ln)
            if m:
                out.append(f"irdic {m['stage']} failed: {m['message']}")
                break
    return out


def show_last(lines: list[str]) -> None:
    """Print ``lines`` to stderr when the process exits: after everything Snakemake prints.

    Snakemake reports a failed job with its rule, inputs and a summary
    after the ``onerror`` handler has run; printing at interpreter exit puts
    the irdic messages last on the screen, each alone on its line, once
    Snakemake has released its locks.
    """
    if not lines:
        return

    def emit():
        sys.stderr.flush()
        sys.stderr.write("\n" + "\n".join(lines) + "\n")
        sys.stderr.flush()

    atexit.register(emit)


@contextlib.contextmanager
def exit_on_error() -> Iterator[None]:
    """Turn an :class:`~irdic.errors.IrdicError` into its one-line message and exit status 1.

    For code that Snakemake runs while it reads the workflow (configuration
    checks in ``workflow/rules/common.smk``): Snakemake would print the
    error with stack lines; a ``SystemExit`` ends it with the message alone.
    """
    try:
        yield
    except IrdicError as exc:
        sys.stderr.write(f"irdic: error: {_one_line(exc)}\n")
        raise SystemExit(1) from None


class Progress:
    """Progress lines ``what: done/total unit, rate unit/s, ETA s`` at about every tenth.

    Parameters
    ----------
    total : int
        Work units (frames, times) to do.
    what : str
        Prefix of the lines (e.g. the function name).
    unit : str
        Name of a work unit.
    logger : logging.Logger
    clock : callable
        Seconds (monotonic); a test may pass a fake one.

    Notes
    -----
    The first reported chunk carries the one-off setup (the first mask,
    stencils, factorisations), so the rate is measured from the end of the
    first update on: ``r = (n - n_1) / (t - t_1)``, the mean over all later
    work (no jumps from a single slow or fast chunk), and the ETA is
    ``(total - n) / r``. Before a second update only the elapsed time is
    known and no rate is claimed.
    """

    def __init__(self, total: int, what: str, *, unit: str = "items", logger: logging.Logger | None = None,
                 clock: Callable[[], float] = time.perf_counter):
        self.total = int(total)
        self.what = what
        self.unit = unit
        self.log = logger if logger is not None else logging.getLogger("irdic")
        self.clock = clock
        self.started = clock()
        self._first = None  # (done, time) after the first update
        self._next = max(1, self.total // 10)

    def update(self, done: int) -> str | None:
        """Report that ``done`` units are finished; returns the line logged, if any."""
        now = self.clock()
        if self._first is None:
            self._first = (done, now)
        if done < self._next and done < self.total:
            return None
        self._next = done + max(1, self.total // 10)
        n1, t1 = self._first
        el = now - self.started
        if done > n1 and now > t1:
            rate = (done - n1) / (now - t1)
            line = (f"{self.what}: {done}/{self.total} {self.unit}, {rate:.3g} {self.unit}/s, "
                    f"ETA {(self.total - done) / rate:.0f} s")
        else:
            line = f"{self.what}: {done}/{self.total} {self.unit}, {el:.1f} s elapsed"
        self.log.info("%s", line)
        return line


class StageProgress:
    """Progress lines and an ETA for a whole stage: its parts weighted by a cost model.

    Parameters
    ----------
    what : str
        Prefix of the lines (the stage's name).
    parts : dict of str to float
        The stage's parts and their expected cost (seconds of one core, from
        the part's size; only their ratios matter).
    threads : int
        The stage's threads (:func:`irdic.threads.thread_budget`); with
        ``shares`` it turns the costs into wall time.
    shares : dict of str to float, optional
        The part of each part's cost that runs on all threads (the rest on one;
        default all of it).
    logger : logging.Logger
    clock : callable
        Seconds (monotonic); a test may pass a fake one.
    tick : float or None
        Seconds between checks for a line while a part runs without reporting
        (a thread of its own while the stage runs; None: no thread, lines on
        reports only).
    beside : iterable of str
        Parts that run on one of the stage's threads beside the others (the
        couple stage's IR clock beside its masks) and report only their start
        and end.

    Notes
    -----
    Parts report the fraction of themselves done (:func:`report`; 0 when they
    start). With ``W`` the expected wall time of all parts, ``w`` that of the
    work reported done and ``s = w / elapsed`` the speed so far, the ETA is
    ``(W - w') / s``, where ``w'`` adds to ``w`` the running part's expected
    share of the time since its last report (at the same speed, at most 90 % of
    the part): a part that reports only its end still moves the ETA on. A
    running part that has reported 20 % of itself or more since its first
    step (its first report of progress; the one-time set-up before it, caches
    and factors, is not repeated) gives its own rest at its own pace
    instead; the parts after it come at ``s``. A part that ends in less than
    half the time expected (it stopped early) takes the weight of the time it
    took. A part run beside the others takes one of the ``n`` threads while
    it runs: it counts as
    ``Δt s / n`` done after ``Δt`` (at most 90 % of it), and ``s`` is the work
    reported done over the elapsed time less ``Δt / n``. The ETA is right as
    far as the model's ratios of the parts are, whatever the machine's speed.
    Lines at about every tenth of ``w' / W``. Used as a
    context manager it is the stage's current one, which :func:`report` feeds
    from anywhere in the stage (its worker threads too).
    """

    def __init__(self, what: str, parts: dict, *, threads: int = 1, shares: dict | None = None,
                 logger: logging.Logger | None = None, clock: Callable[[], float] = time.perf_counter,
                 tick: float | None = 1.0, beside=()):
        self.what = what
        self._shares, self._threads = shares or {}, max(1, int(threads))
        self.weights = {k: self._wall(k, c) for k, c in parts.items()}
        self.total = sum(self.weights.values()) or 1.0
        self.done = dict.fromkeys(self.weights, 0.0)
        self.log = logger if logger is not None else logging.getLogger("irdic")
        self.clock = clock
        self.tick = tick
        self.started = clock()
        self._next = 0.1
        self._lock = threading.Lock()
        self._previous = None
        self._running = None  # (part, time of its last report)
        self._last = None  # (work done, time) at the last report
        self._began = {}  # part: (time, fraction) of its first report
        self._beside = set(beside) & set(self.weights)
        self._beside_since = {}  # part run beside the others: the time it started, while it runs
        self._beside_spans = []  # (start, end) of those that ended
        self._stop = threading.Event()

    def _wall(self, part, cost):
        """Expected wall time of ``part`` at ``cost`` (seconds of one core): its parallel share on the stage's
        threads, the rest on one."""
        share = self._shares.get(part, 1.0)
        return float(cost) * ((1.0 - share) + share / self._threads)

    def reweigh(self, parts: dict) -> None:
        """New expected costs (seconds of one core) of parts that have reported no progress yet (at most their
        start), once the stage knows more of its work than its sizes at the start (the couple stage: the
        specimen's pixels once the points are projected, the masks to build once their reuse is planned); the
        others keep theirs."""
        with self._lock:
            for k, c in parts.items():
                if k in self.weights and self.done[k] == 0.0:
                    self.weights[k] = self._wall(k, c)
            self.total = sum(self.weights.values()) or 1.0

    def fraction(self, now: float | None = None) -> float:
        """The expected part of the stage's wall time done (0..1), the running part extrapolated to ``now``."""
        return self._state(self.clock() if now is None else now)[0]

    def _speed(self):
        """Expected wall seconds of work done per second so far (at the last report), the threads' time taken by
        the parts running beside the others left out."""
        w_last, t_last = self._last
        taken = sum(max(0.0, t_last - t) for t in self._beside_since.values()) / self._threads
        return w_last / max(t_last - self.started - taken, 1e-9)

    def _taken(self, t0, t1):
        """Thread seconds (per thread of the stage) the parts run beside the others took between ``t0`` and
        ``t1``."""
        spans = self._beside_spans + [(t, t1) for t in self._beside_since.values()]
        return sum(max(0.0, min(b, t1) - max(a, t0)) for a, b in spans) / self._threads

    def _beside_done(self, now, speed, parts=None):
        """Work the parts running beside the others (``parts``: those of them) count as done at ``now`` (see the
        Notes)."""
        return sum(min(0.9 * self.weights[k], max(0.0, now - t) * speed / self._threads)
                   for k, t in self._beside_since.items() if parts is None or k in parts)

    def _state(self, now):
        done = sum(self.weights[k] * self.done[k] for k in self.weights)
        if self._last is None:
            return done / self.total, None
        speed = self._speed()
        done += self._beside_done(now, speed)
        if done <= 0:
            return 0.0, None
        if self._running is None:
            return min(1.0, done / self.total), (self.total - done) / speed
        part, since = self._running
        left = self.weights[part] * (1.0 - self.done[part])
        w = done + min(0.9 * left, max(0.0, now - since) * speed)
        eta = (self.total - w) / speed
        t0, f0 = self._began.get(part, (since, self.done[part]))
        f = self.done[part]
        if f - f0 >= OWN_RATE_SHARE and since > t0:
            # the model's ratios between parts are rough; a part's own progress since its first report is not;
            # while a part ran beside it, that one had a thread of it
            pace = (since - t0 - self._taken(t0, since)) / (f - f0)
            own = max(0.0, (1.0 - f) * pace - (now - since))
            eta = own + (self.total - done - left) / speed
        return min(1.0, w / self.total), eta

    def update(self, part: str, fraction: float) -> str | None:
        """Report that ``fraction`` (0..1) of ``part`` is done; returns the line logged, if any."""
        with self._lock:
            if part not in self.done:
                return None
            now = self.clock()
            if part in self._beside:
                return self._beside_update(part, fraction, now)
            if fraction >= 1.0:
                self._shrink_if_short(part, now)
            self.done[part] = max(self.done[part], min(1.0, float(fraction)))
            # its own pace counts from its first step (its first report of progress): before it a part prepares
            # (reads, builds its caches and factors) for a while that its later steps do not repeat
            if self.done[part] > 0.0:
                self._began.setdefault(part, (now, self.done[part]))
            self._running = (part, now) if self.done[part] < 1.0 else None
            w = sum(self.weights[k] * self.done[k] for k in self.weights)
            if w > 0:
                self._last = (w, now)
            return self._line(now)

    def _beside_update(self, part, fraction, now):
        """:meth:`update` of a part run beside the others: its start, or its end (call with the lock held)."""
        if fraction < 1.0:
            self._beside_since.setdefault(part, now)
            return self._line(now)
        if part in self._beside_since and self._last is not None:
            credit = self._beside_done(now, self._speed(), (part,))
            self._beside_spans.append((self._beside_since.pop(part), now))
            left = self.weights[part]
            if credit < SHORT_PART * left:  # it stopped early: the weight of the time it took
                self.total -= left - credit
                self.weights[part] = credit
        self._beside_since.pop(part, None)
        self.done[part] = 1.0
        self._last = (sum(self.weights[k] * self.done[k] for k in self.weights), now)
        return self._line(now)

    def _shrink_if_short(self, part, now):
        """A part that ends in less than :data:`SHORT_PART` of the time the model expected at the speed so far
        (it stopped early: an IR clock that finds no motion) is given the weight of the time it took, so that it
        does not count as fast work; call with the lock held."""
        if self._running is None or self._running[0] != part or self._last is None:
            return
        left = self.weights[part] * (1.0 - self.done[part])
        took = max(0.0, now - self._running[1]) * self._speed()
        if took < SHORT_PART * left:
            self.total -= left - took
            self.weights[part] -= left - took

    def _line(self, now):
        """The line due at ``now`` (logged), if the work crossed the next tenth; call with the lock held."""
        f, eta = self._state(now)
        if f < self._next or eta is None:
            return None
        self._next = (int(f * 10) + 1) / 10
        line = f"{self.what}: {100 * f:.0f} % of the work, {now - self.started:.1f} s elapsed, ETA {eta:.0f} s"
        self.log.info("%s", line)
        return line

    def _ticker(self):
        while not self._stop.wait(self.tick):
            with self._lock:
                self._line(self.clock())

    def __enter__(self):
        global _current
        self._previous, _current = _current, self
        if self.tick:
            threading.Thread(target=self._ticker, daemon=True, name=f"{self.what} progress").start()
        return self

    def __exit__(self, *exc):
        global _current
        self._stop.set()
        _current = self._previous
        return False


#: a part of a StageProgress that ends within this share of the time expected for it is re-weighted to the
#: time it took
SHORT_PART = 0.5

#: a running part that has reported this share of itself done since its first step gives the ETA of its own
#: rest from its own pace since then
OWN_RATE_SHARE = 0.2

#: the StageProgress of the stage being run (None outside one)
_current: StageProgress | None = None


def reweigh(parts: dict) -> None:
    """Give the running stage's :class:`StageProgress` new costs of parts not yet begun (no-op without one)."""
    cur = _current
    if cur is not None:
        cur.reweigh(parts)


def report(part: str, fraction: float) -> None:
    """Tell the running stage's :class:`StageProgress` that ``fraction`` of ``part`` is done (no-op without one)."""
    cur = _current
    if cur is not None:
        cur.update(part, fraction)
