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


rule heat_figure:
    input:
        points=f"{RESULTS}/{{experiment}}/points.zarr",
        fields=f"{RESULTS}/{{experiment}}/fields.zarr",
        heat=f"{RESULTS}/{{experiment}}/heat.zarr",
    output:
        heat=report(
            f"{RESULTS}/{{experiment}}/figures/heat.png",
            caption="../report/heat.rst",
            category="{experiment}",
            subcategory="figures",
            labels={"experiment": "{experiment}", "figure": "heat"},
        ),
    params:
        experiment=lambda wc: wc.experiment,
        times=lambda wc: config["experiments"][wc.experiment]["report"]["times"],
        points=lambda wc: config["experiments"][wc.experiment]["report"]["points"],
        code=code_hash("figures"),
    log:
        f"{RESULTS}/logs/{{experiment}}/heat_figure.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/heat_figure.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/figures.py"
