import os
from pathlib import Path

# Many small factorisations (irdic.image_rbf tiles) run far slower with multi-threaded
# BLAS on a busy 2-core machine; tests run one BLAS thread unless told otherwise.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")


def _blas_kernel() -> str | None:
    """OpenBLAS's Haswell kernels where the CPU has them (x86-64 with AVX2 and FMA), else None.

    OpenBLAS picks its kernels by CPU (AVX2 or AVX-512 on today's x86-64), and
    they round differently in the last bits, which ill-conditioned RBF systems
    amplify to ~1e-6: tests/test_golden.py compares at 1e-9 only when every run
    uses the same kernels, whichever machine it is on.
    """
    try:
        flags = Path("/proc/cpuinfo").read_text().split()
    except OSError:
        return None
    return "Haswell" if "avx2" in flags and "fma" in flags else None


if os.environ.get("OPENBLAS_CORETYPE") is None and (_kernel := _blas_kernel()) is not None:
    os.environ["OPENBLAS_CORETYPE"] = _kernel

import pytest

ROOT = Path(__file__).resolve().parents[1]
# IRDIC_SAMPLES points elsewhere (a checkout whose parent folder has no shared/samples)
SAMPLES = Path(os.environ.get("IRDIC_SAMPLES", ROOT.parent / "shared" / "samples"))
#: the real files whose licences allow shipping them (each folder with its licence), read first
SHIPPED = ROOT / "tests" / "data"


class _Samples:
    """``samples / "irb" / "AA011400.irb"``: a real file, from ``tests/data`` or else ``../shared/samples``.

    Each file is looked up in ``tests/data`` first (the files whose licences
    allow shipping them), then in ``../shared/samples`` (the GPL FLIR
    sequences and the unlicensed IRBIS exports are only there). A file found
    in neither skips the test that asks for it, naming both places.
    """

    def __init__(self, roots, parts=()):
        self.roots = tuple(roots)
        self.parts = tuple(parts)

    def __truediv__(self, part: str):
        parts = (*self.parts, part)
        if not self.parts:
            return _Samples(self.roots, parts)
        for root in self.roots:
            if root.joinpath(*parts).exists():
                return root.joinpath(*parts)
        where = "/".join(parts)
        pytest.skip(f"real sample file {where!r} found neither in {SHIPPED} nor in {SAMPLES}")


@pytest.fixture(scope="session")
def samples() -> _Samples:
    """The real sample exports: ``samples / "<folder>" / "<file>"`` (see :class:`_Samples`)."""
    return _Samples((SHIPPED, SAMPLES))
