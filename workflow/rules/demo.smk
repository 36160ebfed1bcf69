# The bundled synthetic demo: raw exports in real formats plus the analytic truth.


rule demo:
    output:
        manifest=DEMO_MANIFEST,
    params:
        outdir=lambda wildcards, output: os.path.dirname(output.manifest),
        scale=DEMO["scale"],
        ir_noise=DEMO["ir_noise"],
        dic_noise=DEMO["dic_noise"],
        seed=DEMO["seed"],
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
        "../../scripts/make_demo.py"
