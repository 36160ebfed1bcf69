# points.zarr (+ fields.zarr) -> figures for `snakemake --report`, a ParaView time series and a CSV table.
# Include after fields.smk: without a fields rule the figures and the export use points.zarr alone
# (experiment_results() in common.smk) and there is no strain figure and no load figure (the signals are in fields.zarr).

rule figures:
    input:
        unpack(experiment_results),
    output:
        **{
            name: report(
                f"{RESULTS}/{{experiment}}/figures/{name}.png",
                caption=f"../report/{name}.rst",
                category="{experiment}",
                subcategory="figures",
                labels={"experiment": "{experiment}", "figure": name},
            )
            for name in figure_names()
        },
    params:
        experiment=lambda wc: wc.experiment,
        times=lambda wc: config["experiments"][wc.experiment]["report"]["times"],
        points=lambda wc: config["experiments"][wc.experiment]["report"]["points"],
        code=code_hash("figures"),
    log:
        f"{RESULTS}/logs/{{experiment}}/figures.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/figures.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/figures.py"

rule export:
    input:
        unpack(export_inputs),
    output:
        paraview=directory(f"{RESULTS}/{{experiment}}/paraview"),
        csv=f"{RESULTS}/{{experiment}}/points.csv",
    params:
        experiment=lambda wc: wc.experiment,
        points=lambda wc: config["experiments"][wc.experiment]["report"]["points"],
        settings=config["export"],
        code=code_hash("export"),
    log:
        f"{RESULTS}/logs/{{experiment}}/export.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/export.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/export.py"

rule report_html:
    input:
        figures=report_figures(),
        stores=report_stores(),
    output:
        html=f"{RESULTS}/report.html",
    params:
        title=", ".join(os.path.relpath(f) for f in workflow.configfiles) or "the workflow's configuration",
        settings=irdic.config.non_defaults(config),
        code=code_hash("report"),
    log:
        f"{RESULTS}/logs/report.log",
    benchmark:
        f"{RESULTS}/benchmarks/report.tsv"
    threads: 1
    resources:
        mem_mb=1000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/report.py"
