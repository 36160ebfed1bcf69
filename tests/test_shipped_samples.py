"""The real files shipped under tests/data: licensed, unchanged, and what the sample tests read first."""

import hashlib

import pytest

from tests.conftest import SAMPLES, SHIPPED, _Samples

FOLDERS = {"irb": ("AA011400.irb", "AB020300.irb"), "dice": ("DICe_solution_0.txt", "DICe_solution_1.txt")}


@pytest.mark.parametrize("folder", sorted(FOLDERS))
def test_each_shipped_folder_has_its_licence_and_origin(folder):
    d = SHIPPED / folder
    assert (d / "LICENSE").stat().st_size > 1000
    note = (d / "README.md").read_text(encoding="utf-8")
    assert "licen" in note.lower() and "public repository" in note
    for name in FOLDERS[folder]:
        assert (d / name).stat().st_size > 100_000 and name in note


@pytest.mark.parametrize("folder", sorted(FOLDERS))
def test_shipped_files_are_unchanged_copies(folder):
    if not (SAMPLES / folder).is_dir():
        pytest.skip(f"{SAMPLES / folder} absent: nothing to compare with")
    for name in (*FOLDERS[folder], "LICENSE"):
        a, b = (SHIPPED / folder / name).read_bytes(), (SAMPLES / folder / name).read_bytes()
        assert hashlib.sha256(a).digest() == hashlib.sha256(b).digest(), name


def test_a_fresh_clone_reads_the_shipped_files_and_skips_only_the_unshipped(tmp_path):
    fresh = _Samples((SHIPPED, tmp_path / "no-shared-samples"))
    assert fresh / "irb" / "AA011400.irb" == SHIPPED / "irb" / "AA011400.irb"
    assert fresh / "dice" / "DICe_solution_0.txt" == SHIPPED / "dice" / "DICe_solution_0.txt"
    with pytest.raises(pytest.skip.Exception, match="'irbis-text/GW_1_Z2_860.txt' found neither"):
        fresh / "irbis-text" / "GW_1_Z2_860.txt"
    # the GPL FLIR sequences are not shipped: looked up in ../shared/samples only
    with pytest.raises(pytest.skip.Exception, match="'flir/SampleSEQ.seq' found neither"):
        fresh / "flir" / "SampleSEQ.seq"
