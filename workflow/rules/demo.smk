# The bundled synthetic demo: raw exports in real formats plus the analytic truth.
# A checkpoint: the ingest and calibrate rules take the files it wrote as their inputs
# (raw_files in common.smk), so editing one of them re-runs what reads it.


checkpoint demo:
    output:
        manifest=DEMO_MANIFEST,
    params:
        settings={k: v for k, v in DEMO.items() if k not in ("enabled", "outdir")},
        code=code_hash("demo"),
    log:
        f"{RESULTS}/logs/demo.log",
    benchmark:
        f"{RESULTS}/benchmarks/demo.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/demo.py"
