# points.zarr + calibration -> in-plane temperature gradient, temperature rate and strain,
# with the testing machine signals of dic.zarr (and machine.zarr when configured) at the DIC times.


rule fields:
    input:
        unpack(fields_inputs),
    output:
        store=directory(f"{RESULTS}/{{experiment}}/fields.zarr"),
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
