"""A change of irdic's code re-runs exactly the stages that use it (via the rules' params)."""

import shutil
import sys
from pathlib import Path

import pytest

import irdic.codehash as ch


@pytest.fixture
def pkg(tmp_path, monkeypatch):
    """A copy of the irdic package that the hashes read instead of the real one."""
    pkg = tmp_path / "irdic"
    shutil.copytree(Path(ch.__file__).parent, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(ch, "_ROOT", pkg)
    ch.code_hash.cache_clear()
    yield pkg
    ch.code_hash.cache_clear()


def _edit(path: Path):
    path.write_text(path.read_text() + "\n# changed\n")
    ch.code_hash.cache_clear()


def test_every_irdic_module_a_stage_imports_is_hashed():
    """Importing the stage entry (in a fresh interpreter) loads no irdic module outside its hashed set."""
    import subprocess

    root = Path(ch.__file__).resolve().parents[1]
    for stage in ch.STAGES:
        code = (f"import sys, irdic.stages.{stage}; "
                "print('\\n'.join(m.__file__ for n, m in sys.modules.items() "
                "if (n == 'irdic' or n.startswith('irdic.')) and getattr(m, '__file__', None)))")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, check=True,
                             env={"PYTHONPATH": str(root), "PATH": ""}).stdout.split()
        loaded = {str(Path(f).resolve().relative_to(Path(ch.__file__).resolve().parent)) for f in out}
        assert loaded <= set(ch.stage_modules(stage)), (stage, loaded - set(ch.stage_modules(stage)))


def test_lazy_imports_inside_functions_are_followed():
    # plot_experiment is imported inside the figures entry, load_camera inside plot.calibration
    assert "plot/experiment.py" in ch.stage_modules("figures")
    assert "signals.py" in ch.stage_modules("fields")  # imported inside fields.run
    assert "stages/couple.py" not in ch.stage_modules("fields")
    assert not [m for m in ch.stage_modules("fields") if m.startswith("coupling/")]
    with pytest.raises(KeyError, match="unknown stage 'ingest'"):
        ch.stage_modules("ingest")


def test_editing_validation_changes_the_couple_hash(pkg):
    before = {stage: ch.code_hash(stage) for stage in ch.STAGES}
    assert len(set(before.values())) == len(before)  # every stage has its own set of modules
    # the argument checks (irdic/validation.py; irdic/_checks.py in older layouts) feed couple
    for name in ("_checks.py", "validation.py"):
        if (pkg / name).exists():
            _edit(pkg / name)
            assert ch.code_hash("couple") != before["couple"], name
    (pkg / "validation.py").write_text("# the one argument-check module\n")
    (pkg / "stages" / "couple.py").write_text((pkg / "stages" / "couple.py").read_text()
                                              + "\nfrom .. import validation  # noqa\n")
    ch.code_hash.cache_clear()
    mid = ch.code_hash("couple")
    _edit(pkg / "validation.py")
    assert ch.code_hash("couple") != mid


def test_an_edit_reruns_exactly_the_stages_that_import_it(pkg):
    before = {stage: ch.code_hash(stage) for stage in ch.STAGES}
    _edit(pkg / "footprint" / "visibility.py")
    changed = {s for s in before if before[s] != ch.code_hash(s)}
    assert changed == {"couple"}
    # the fields stage's noise probes extrapolate as the couple stage does: both re-run, and the heat stage,
    # which takes the IR pixel's size on the surface from the same module as the fields stage
    mid = {stage: ch.code_hash(stage) for stage in ch.STAGES}
    _edit(pkg / "footprint" / "extrapolation.py")
    assert {s for s in mid if mid[s] != ch.code_hash(s)} == {"couple", "fields", "heat"}
    after = {stage: ch.code_hash(stage) for stage in ch.STAGES}
    _edit(pkg / "io" / "irbis.py")
    changed = {s for s in after if after[s] != ch.code_hash(s)}
    # every stage that reads or writes IR exports (irdic.io is one package: its __init__ imports the readers)
    assert {"demo", "ingest_ir", "calibrate"} <= changed
    assert {s for s in ch.STAGES if "io/irbis.py" in ch.stage_modules(s)} == changed
