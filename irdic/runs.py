"""Which jobs of :func:`irdic.pipeline.run` are up to date, so that a re-run redoes only what changed.

A job (one stage for one setup or experiment) is described by a key: the
stage, the hash of the irdic code it runs (:func:`irdic.codehash.code_hash`),
its parameters and a fingerprint of each input. After the job has written
its outputs, :class:`Ledger` records the key and a fingerprint of each
output in ``<results>/.irdic/runs/<job>.json``. The next run skips the job
when the key is the same and every output is still the one it wrote; any
difference (a parameter, an edited or added input file, new code, an output
rewritten or removed by someone else) runs it again, and so do the jobs
downstream, whose input fingerprints change with it.

Fingerprints: a zarr store by the bytes of its ``zarr.json`` (it carries
the time it was written and its chunk manifest, :mod:`irdic.store`), any
other file by its size and modification time (ns), a folder by those of
every file in it.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from pathlib import Path
from typing import Iterable, Mapping

from .store import jsonable

__all__ = ["Ledger", "fingerprint", "LEDGER_DIR"]

log = logging.getLogger(__name__)

#: folder (under the results folder) of the job records
LEDGER_DIR = Path(".irdic") / "runs"


def _file_print(p: Path) -> list:
    st = p.stat()
    return [st.st_size, st.st_mtime_ns]


def fingerprint(path: str | os.PathLike) -> object:
    """What identifies the present content of ``path``: None when it is absent.

    Parameters
    ----------
    path : path-like
        A zarr store, another folder, or a file.

    Returns
    -------
    object
        JSON-able: the SHA-256 of ``zarr.json`` for a store, ``[size, mtime_ns]``
        for a file, ``{relative path: [size, mtime_ns]}`` for a folder.
    """
    p = Path(path)
    try:
        if (p / "zarr.json").is_file():
            return "zarr:" + hashlib.sha256((p / "zarr.json").read_bytes()).hexdigest()
        if p.is_dir():
            return {str(f.relative_to(p)): _file_print(f) for f in sorted(p.rglob("*")) if f.is_file()}
        if p.is_file():
            return _file_print(p)
    except OSError:
        return None
    return None


class Ledger:
    """The records of the jobs of a results folder.

    Parameters
    ----------
    results : path-like
        The results folder.
    force : bool
        Run every job whatever the records say (they are still updated).
    """

    def __init__(self, results: str | os.PathLike, *, force: bool = False):
        self.root = Path(results) / LEDGER_DIR
        self.force = force
        self.skipped: list[str] = []

    def _path(self, job: str) -> Path:
        return self.root / (job.replace(os.sep, "__") + ".json")

    @staticmethod
    def key(code: str, params: Mapping | None, inputs: Iterable) -> str:
        """The key of a job: its code hash, parameters and the fingerprints of its inputs."""
        text = json.dumps({"code": code, "params": jsonable(dict(params or {})),
                           "inputs": [[os.fspath(i), fingerprint(i)] for i in inputs]},
                          sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()

    def fresh(self, job: str, key: str, outputs: Iterable) -> bool:
        """True when ``job`` last ran with ``key`` and its outputs are still the ones it wrote."""
        if self.force:
            return False
        try:
            rec = json.loads(self._path(job).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        now = {os.fspath(o): fingerprint(o) for o in outputs}
        if rec.get("key") != key or any(v is None for v in now.values()):
            return False
        return json.loads(json.dumps(now)) == rec.get("outputs")

    def record(self, job: str, key: str, outputs: Iterable) -> None:
        """Remember that ``job`` ran with ``key`` and wrote ``outputs`` (written whole, then renamed)."""
        path = self._path(job)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}")
        tmp.write_text(json.dumps({"key": key, "outputs": {os.fspath(o): fingerprint(o) for o in outputs}},
                                  sort_keys=True), encoding="utf-8")
        os.replace(tmp, path)

    def run(self, job: str, code: str, params: Mapping | None, inputs: Iterable, outputs: Iterable, fn) -> bool:
        """Run ``fn()`` unless ``job`` is up to date; True when it ran."""
        inputs, outputs = list(inputs), list(outputs)
        key = self.key(code, params, inputs)
        if self.fresh(job, key, outputs):
            log.info("%s: up to date (inputs, parameters and code unchanged), skipped", job)
            self.skipped.append(job)
            return False
        fn()
        self.record(job, key, outputs)
        return True
