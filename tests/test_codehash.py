"""A change of irdic's code re-runs exactly the stages that use it (via the rules' params)."""

import shutil
from pathlib import Path

import irdic.codehash as ch


def test_code_hash_follows_the_stage_modules(tmp_path, monkeypatch):
    pkg = tmp_path / "irdic"
    shutil.copytree(Path(ch.__file__).parent, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(ch, "_ROOT", pkg)
    ch.code_hash.cache_clear()
    before = {stage: ch.code_hash(stage) for stage in ch.STAGE_MODULES}
    assert len(set(before.values())) == len(before)  # every stage has its own set of modules
    (pkg / "couple.py").write_text((pkg / "couple.py").read_text() + "\n# changed\n")
    ch.code_hash.cache_clear()
    after = {stage: ch.code_hash(stage) for stage in ch.STAGE_MODULES}
    changed = {s for s in before if before[s] != after[s]}
    assert changed == {s for s, mods in ch.STAGE_MODULES.items() if "couple.py" in mods} == {"couple"}
    (pkg / "io" / "irbis.py").write_text((pkg / "io" / "irbis.py").read_text() + "\n# changed\n")
    ch.code_hash.cache_clear()
    changed = {s for s in after if after[s] != ch.code_hash(s)}
    assert changed == {"demo", "ingest", "calibrate"}  # the stages that read IR exports
    ch.code_hash.cache_clear()
