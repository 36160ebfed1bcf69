# DIC points + IR frames + calibration -> temperatures, pixel gradients and local rates at the points.
# With execution.chunk_frames > 0 a long record is split into time chunks, one couple_chunk job each
# (results/<experiment>/chunks/points-<i>.zarr), which couple then gathers into points.zarr.


rule couple_chunk:
    input:
        unpack(couple_chunk_inputs),
    output:
        store=directory(f"{RESULTS}/{{experiment}}/chunks/points-{{i}}.zarr"),
    params:
        settings=config["interpolation"],
        code=code_hash("couple"),
        chunk=chunk_of,
    wildcard_constraints:
        i=r"\d+",
    log:
        f"{RESULTS}/logs/{{experiment}}/couple-{{i}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/{{experiment}}/couple-{{i}}.tsv"
    threads: 2
    resources:
        mem_mb=4000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/couple.py"


rule couple:
    input:
        unpack(couple_inputs),
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
