"""The tiny demo through Snakemake's slurm executor on a real (single-node) SLURM cluster.

Bring the cluster up first, as root: ``tools/local-slurm up`` (``.ci/run`` does). Without
it the cluster test is skipped with the reason; with ``IRDIC_REQUIRE_SLURM=1`` (CI, after
``up``) a missing cluster fails the test instead, so CI cannot pass by skipping.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import xarray as xr
import yaml

from irdic.store import open_store

ROOT = Path(__file__).resolve().parents[1]
PROFILE = ROOT / "profiles" / "slurm-local"
SLURM_TOOLS = ("sinfo", "sbatch", "squeue", "srun", "scontrol")
# SLURM keeps finished jobs visible this long; they are the evidence the jobs ran there
READY_STATES = {"idle", "mix", "mixed", "alloc", "allocated"}


def _slurm_conf() -> Path:
    if os.environ.get("SLURM_CONF"):
        return Path(os.environ["SLURM_CONF"])
    return Path(os.environ.get("IRDIC_SLURM_DIR", "/tmp/irdic-slurm")) / "slurm.conf"


def _unavailable(reason: str):
    if os.environ.get("IRDIC_REQUIRE_SLURM") == "1":
        pytest.fail(f"IRDIC_REQUIRE_SLURM=1 but {reason}")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def slurm_env():
    """Environment whose SLURM commands reach a cluster with an idle node; skip without one."""
    missing = [t for t in SLURM_TOOLS if shutil.which(t) is None]
    if missing:
        _unavailable(f"SLURM client commands not found ({', '.join(missing)}); "
                     "run 'tools/local-slurm up' as root to install and start a local cluster")
    conf = _slurm_conf()
    if not conf.is_file():
        _unavailable(f"no SLURM configuration at {conf}; run 'tools/local-slurm up' as root "
                     "(or set SLURM_CONF)")
    env = dict(os.environ, SLURM_CONF=str(conf))
    try:
        res = subprocess.run(["sinfo", "-h", "-N", "-o", "%t"], env=env, capture_output=True,
                             text=True, timeout=20)
    except subprocess.TimeoutExpired:
        _unavailable(f"sinfo (SLURM_CONF={conf}) did not answer within 20 s")
    states = set(res.stdout.split())
    if res.returncode != 0 or not states & READY_STATES:
        _unavailable(f"the SLURM cluster of {conf} is not up (sinfo: "
                     f"{(res.stdout + res.stderr).strip() or 'no nodes'}); run 'tools/local-slurm up'")
    return env


def _config():
    with open(ROOT / "config" / "config.yaml") as fh:
        cfg = yaml.safe_load(fh)
    cfg["demo"]["scale"] = "tiny"
    # the half-shell alone runs every rule; the tube's coupling would add minutes on 2 cores
    cfg["experiments"] = {"halfshell": cfg["experiments"]["halfshell"]}
    # time chunks on: the tiny half-shell's 5 DIC times in 3 couple_chunk and 3 fields_chunk jobs
    cfg["execution"] = {"chunk_frames": 2}
    return cfg


def _start_snakemake(workdir: Path, args, env):
    workdir.mkdir(parents=True, exist_ok=True)
    with open(workdir / "config.yaml", "w") as fh:
        yaml.safe_dump(_config(), fh)
    cmd = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"),
           "--directory", str(workdir), "--configfile", str(workdir / "config.yaml"), *args]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _finish(proc, timeout):
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()  # Snakemake's slurm executor cancels its jobs on the way out
        _, err = proc.communicate()
        pytest.fail(f"{' '.join(proc.args)} ran longer than {timeout} s:\n{err[-4000:]}")
    assert proc.returncode == 0, f"{' '.join(proc.args)} failed:\n{err[-4000:]}"


def _stores(work: Path) -> dict[str, Path]:
    return {str(p.relative_to(work)): p for top in ("results", "resources")
            for p in sorted((work / top).rglob("*.zarr"))}


def _profile(path: Path) -> dict:
    with open(path / "config.yaml") as fh:
        return yaml.safe_load(fh)


def test_local_profile_is_the_slurm_profile_plus_the_local_cluster():
    slurm, local = _profile(ROOT / "profiles" / "slurm"), _profile(PROFILE)
    for key in ("slurm_account", "slurm_partition"):
        local["default-resources"].pop(key)
        slurm["default-resources"].pop(key)
    local_only = {"slurm-status-command", "slurm-init-seconds-before-status-checks",
                  "slurm-keep-successful-logs"}
    assert local.pop("slurm-status-command") == "squeue"  # no accounting storage: no sacct
    assert {k: v for k, v in local.items() if k not in local_only} == slurm


@pytest.mark.slow
@pytest.mark.cluster
def test_demo_on_slurm_matches_the_local_run(slurm_env, tmp_path):
    on_slurm, local = tmp_path / "slurm", tmp_path / "local"
    logs = tmp_path / "slurm-logs"
    prefix = f"irdic-test-{os.getpid()}"
    # side by side: the SLURM run mostly waits for its status queries
    slurm_run = _start_snakemake(on_slurm, ["--profile", str(PROFILE), "--slurm-logdir", str(logs),
                                            "--slurm-jobname-prefix", prefix], slurm_env)
    local_run = _start_snakemake(local, ["--cores", "2"], slurm_env)
    _finish(local_run, timeout=1200)
    _finish(slurm_run, timeout=1200)

    # every job but the aggregating target rule ran as a SLURM job and left its log
    job_logs = sorted(logs.rglob("*.log"))
    rules = {p.relative_to(logs).parts[0].removeprefix("rule_") for p in job_logs}
    assert rules >= {"demo", "ingest_ir", "ingest_dic", "calibrate", "couple", "fields",
                     "figures", "export"}, rules
    job_ids = [p.stem for p in job_logs]
    assert all(j.isdigit() for j in job_ids), job_ids
    # slurmctld keeps finished jobs for MinJobAge (600 s on the local cluster)
    res = subprocess.run(["squeue", "-h", "--states=all", "-o", "%i %T %j", "-j", ",".join(job_ids)],
                         env=slurm_env, capture_output=True, text=True, timeout=30)
    jobs = {i: (state, name) for i, state, name in (line.split() for line in res.stdout.splitlines())}
    assert jobs.keys() == set(job_ids), res.stdout + res.stderr
    assert all(state == "COMPLETED" and name.startswith(prefix) for state, name in jobs.values()), jobs

    stores = _stores(on_slurm)
    assert stores.keys() == _stores(local).keys()
    # ir, dic, points, fields, calibration and the demo's truths
    assert len(stores) >= 7, stores.keys()
    for rel, path in stores.items():
        # provenance (creation time, host) lives in attrs, which assert_allclose ignores
        a, b = open_store(path), open_store(local / rel)
        assert set(a.data_vars) == set(b.data_vars), rel
        xr.testing.assert_allclose(a.load(), b.load(), rtol=1e-12, atol=1e-12)
