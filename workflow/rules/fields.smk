# points.zarr + calibration -> in-plane temperature gradient, temperature rate and strain.


rule fields:
    input:
        points=f"{RESULTS}/{{experiment}}/points.zarr",
        calibration=lambda wc: f"{RESULTS}/setups/{config['experiments'][wc.experiment]['setup']}/calibration.zarr",
    output:
        directory(f"{RESULTS}/{{experiment}}/fields.zarr"),
    params:
        settings=config["fields"],
        code=code_hash("fields"),
    log:
        f"{RESULTS}/logs/{{experiment}}/fields.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/fields.tsv"
    threads: 2
    resources:
        mem_mb=6000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/fields.py"
