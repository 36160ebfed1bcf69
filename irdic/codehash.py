"""A short hash of irdic's own source code, per stage.

Snakemake re-runs a job when its ``params`` change, but it does not look
inside an installed Python package. Each rule passes the hash of the irdic
modules its stage uses as a parameter, so editing or upgrading that code
re-runs exactly the stages it affects.
"""

from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path

__all__ = ["code_hash", "STAGE_MODULES"]

_ROOT = Path(__file__).resolve().parent

#: irdic modules (files or sub-packages, relative to the package) each stage depends on.
STAGE_MODULES: dict[str, tuple[str, ...]] = {
    "demo": ("synthetic", "io", "store.py"),
    "ingest": ("io", "ingest.py", "signals.py", "store.py"),
    "calibrate": ("io", "camera", "calibration", "plot.py", "store.py"),
    "couple": ("camera", "footprint.py", "pointcloud.py", "image_rbf", "numerics", "validation.py",
               "couple.py", "store.py"),
    "figures": ("plot.py", "export.py", "pipeline.py", "store.py"),
    "export": ("export.py", "pipeline.py", "store.py"),
    "fields": ("camera", "surface", "numerics", "gradient.py", "strain.py", "pointcloud.py",
               "validation.py", "fields.py", "signals.py",
               "io/signals.py", "io/table.py", "store.py"),
}


@lru_cache(maxsize=None)
def code_hash(*parts: str) -> str:
    """SHA-256 (first 12 hex digits) of the given irdic modules' source files.

    Parameters
    ----------
    *parts : str
        Module files (``"ingest.py"``) or sub-package folders (``"io"``)
        relative to the irdic package; a stage name of :data:`STAGE_MODULES`
        stands for its modules. Missing entries are skipped (a stage whose
        module does not exist yet hashes what exists).
    """
    names: list[str] = []
    for p in parts:
        names.extend(STAGE_MODULES.get(p, (p,)))
    h = hashlib.sha256()
    for name in sorted(set(names)):
        target = _ROOT / name
        files = sorted(target.rglob("*.py")) if target.is_dir() else [target]
        for f in files:
            if f.is_file():
                h.update(str(f.relative_to(_ROOT)).encode())
                h.update(f.read_bytes())
    return h.hexdigest()[:12]
