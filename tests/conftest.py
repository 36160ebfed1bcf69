import os

# Many small factorisations (irdic.image_rbf tiles) run far slower with multi-threaded
# BLAS on a busy 2-core machine; tests run one BLAS thread unless told otherwise.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# IRDIC_SAMPLES points elsewhere (a checkout whose parent folder has no shared/samples)
SAMPLES = Path(os.environ.get("IRDIC_SAMPLES", ROOT.parent / "shared" / "samples"))


@pytest.fixture(scope="session")
def samples() -> Path:
    """The folder of real sample exports (``../shared/samples``); skip when absent."""
    if not SAMPLES.is_dir():
        pytest.skip(f"real sample files not found at {SAMPLES}")
    return SAMPLES
