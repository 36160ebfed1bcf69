# Raw exports -> dic.zarr and ir.zarr, one pair per experiment.


rule ingest_ir:
    input:
        experiment_files("ir"),
    output:
        store=directory(f"{RESULTS}/{{experiment}}/ir.zarr"),
    params:
        path=lambda wc: config["experiments"][wc.experiment]["ir"]["path"],
        settings=source_settings("ir"),
        code=code_hash("ingest_ir"),
    log:
        f"{RESULTS}/logs/{{experiment}}/ingest_ir.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/ingest_ir.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/ingest_ir.py"


rule ingest_dic:
    input:
        experiment_files("dic"),
    output:
        store=directory(f"{RESULTS}/{{experiment}}/dic.zarr"),
    params:
        path=lambda wc: config["experiments"][wc.experiment]["dic"]["path"],
        settings=source_settings("dic"),
        code=code_hash("ingest_dic"),
    log:
        f"{RESULTS}/logs/{{experiment}}/ingest_dic.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/ingest_dic.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/ingest_dic.py"


# Only requested for experiments with a `machine:` record (all_outputs, fields_inputs in common.smk).
rule ingest_machine:
    input:
        raw=lambda wc: raw_files(config["experiments"][wc.experiment]["machine"]["path"]),
        ir=f"{RESULTS}/{{experiment}}/ir.zarr",
    output:
        store=directory(f"{RESULTS}/{{experiment}}/machine.zarr"),
    params:
        path=lambda wc: config["experiments"][wc.experiment]["machine"]["path"],
        settings=source_settings("machine"),
        code=code_hash("ingest_machine"),
    log:
        f"{RESULTS}/logs/{{experiment}}/ingest_machine.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/ingest_machine.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/ingest_machine.py"
