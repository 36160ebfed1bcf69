# fields.zarr + points.zarr -> heat.zarr: the heat source of the local heat balance of a thin wall
# (docs/heat.md), for the experiments with a material block (heat_experiments() in common.smk).


rule heat:
    input:
        fields=f"{RESULTS}/{{experiment}}/fields.zarr",
        points=f"{RESULTS}/{{experiment}}/points.zarr",
    output:
        store=directory(f"{RESULTS}/{{experiment}}/heat.zarr"),
    params:
        material=lambda wc: config["experiments"][wc.experiment]["material"],
        fields=config["fields"],
        code=code_hash("heat"),
    log:
        f"{RESULTS}/logs/{{experiment}}/heat.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/heat.tsv"
    threads: 2
    resources:
        mem_mb=6000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/heat.py"
