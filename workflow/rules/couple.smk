# DIC points + IR frames + calibration -> temperatures, pixel gradients and local rates at the points.


rule couple:
    input:
        dic=f"{RESULTS}/{{experiment}}/dic.zarr",
        ir=f"{RESULTS}/{{experiment}}/ir.zarr",
        calibration=lambda wc: f"{RESULTS}/setups/{config['experiments'][wc.experiment]['setup']}/calibration.zarr",
    output:
        store=directory(f"{RESULTS}/{{experiment}}/points.zarr"),
    params:
        settings=config["interpolation"],
        code=code_hash("couple"),
    log:
        f"{RESULTS}/logs/{{experiment}}/couple.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/couple.tsv"
    threads: 2
    resources:
        mem_mb=4000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/couple.py"
