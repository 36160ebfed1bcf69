# One IR image of the reference object + the DIC marker export -> the IR camera in the DIC frame.


rule calibrate:
    input:
        unpack(setup_files),
    output:
        store=directory(f"{RESULTS}/setups/{{setup}}/calibration.zarr"),
        figure=report(
            f"{RESULTS}/setups/{{setup}}/calibration.png",
            caption="../report/calibration.rst",
            category="Calibration",
            subcategory="{setup}",
            labels={"setup": "{setup}", "figure": "calibration"},
        ),
    params:
        markers=lambda wc: config["setups"][wc.setup]["markers"]["path"],
        target=lambda wc: config["setups"][wc.setup]["target_image"]["path"],
        target_format=lambda wc: config["setups"][wc.setup]["target_image"]["format"],
        seeds=lambda wc: config["setups"][wc.setup]["seeds"],
        settings=config["calibration"],
        code=code_hash("calibrate"),
    log:
        f"{RESULTS}/logs/setups/{{setup}}/calibrate.log",
    benchmark:
        f"{RESULTS}/benchmarks/setups/{{setup}}/calibrate.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        "../envs/irdic.yaml"
    script:
        "../../scripts/calibrate.py"
