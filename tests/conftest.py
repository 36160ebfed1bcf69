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
#: the real files whose licences allow shipping them (each folder with its licence), read first
SHIPPED = ROOT / "tests" / "data"


class _Samples:
    """``samples / "irb"``: that folder of real files, from ``tests/data`` or else ``../shared/samples``.

    A folder found in neither skips the test that asks for it, naming both
    places (files without a licence to ship, such as ``irbis-text``, are only
    in ``../shared/samples``).
    """

    def __init__(self, roots):
        self.roots = tuple(roots)

    def __truediv__(self, folder: str) -> Path:
        for root in self.roots:
            if (root / folder).is_dir():
                return root / folder
        pytest.skip(f"real sample folder {folder!r} found neither in {SHIPPED} nor in {SAMPLES}")


@pytest.fixture(scope="session")
def samples() -> _Samples:
    """The real sample exports: ``samples / "<folder>" / "<file>"`` (see :class:`_Samples`)."""
    return _Samples((SHIPPED, SAMPLES))
