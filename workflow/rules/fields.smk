# points.zarr + calibration -> in-plane temperature gradient, temperature rate and strain,
# with the testing machine signals of dic.zarr (and machine.zarr when configured) at the DIC times.
# With execution.chunk_frames > 0: one fields_chunk job per time chunk
# (results/<experiment>/chunks/fields-<i>.zarr), gathered by fields into fields.zarr.


rule fields_chunk:
    input:
        unpack(fields_inputs),
    output:
        store=directory(f"{RESULTS}/{{experiment}}/chunks/fields-{{i}}.zarr"),
    params:
        settings=config["fields"],
        code=code_hash("fields"),
        chunk=chunk_of,
    wildcard_constraints:
        i=r"\d+",
    log:
        f"{RESULTS}/logs/{{experiment}}/fields-{{i}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/fields-{{i}}.tsv"
    threads: 2
    resources:
        mem_mb=6000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/fields.py"


rule fields:
    input:
        unpack(fields_gather_inputs),
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
