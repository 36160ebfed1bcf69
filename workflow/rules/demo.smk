# The bundled synthetic demo: raw exports in real formats plus the analytic truth.


rule demo:
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
