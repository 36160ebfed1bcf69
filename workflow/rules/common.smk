# Configuration, lookups and input functions shared by all rules.

import os
import re
import time

import irdic.chunks
import irdic.config
import irdic.logs
import irdic.pipeline
from irdic.codehash import code_hash
import irdic.plot
from irdic.synthetic.experiments import n_stages as demo_stages
from irdic.ingest.inputs import list_inputs

STARTED = time.time()
# a configuration error ends the run with its one-line message, without stack lines
with irdic.logs.exit_on_error():
    # Snakemake's own YAML loader keeps the last of two equal keys: an experiment copied under its old name would vanish
    for _configfile in workflow.configfiles:
        irdic.config.load_yaml(_configfile)
    # --config hands nested values over as strings: numbers where the schema wants them
    irdic.config.command_line_values(config, dict(workflow.config_settings.config))
    irdic.config.validate_config(config)
    # outputs must stay inside the results folder whatever the names (links included)
    irdic.pipeline.stage_paths(config)
    # every missing input folder at once, named by its key, before Snakemake's input functions meet the first
    irdic.pipeline.check_inputs(config)

RESULTS = config["results"]
DEMO = config["demo"]
SETUPS = list(config["setups"])
EXPERIMENTS = list(config["experiments"])
DEMO_MANIFEST = f"{DEMO['outdir']}/manifest.yaml"


onerror:
    # the failed stages' one-line messages, last on the screen (after Snakemake's job report)
    irdic.logs.show_last(irdic.logs.failures(f"{RESULTS}/logs", since=STARTED))


wildcard_constraints:
    experiment="|".join(map(re.escape, EXPERIMENTS)) or "NONE",
    setup="|".join(map(re.escape, SETUPS)) or "NONE",


def _in_demo(path):
    """True when a configured path lies in the generated demo folder."""
    if not DEMO["enabled"]:
        return False
    demo = os.path.normpath(DEMO["outdir"])
    return os.path.normpath(path).startswith(demo + os.sep) or os.path.normpath(path) == demo


def raw_files(path):
    """Input files for a configured path: its files (in the demo: once the demo checkpoint wrote them)."""
    if _in_demo(path):
        checkpoints.demo.get()
        with irdic.logs.exit_on_error():
            return [DEMO_MANIFEST] + [str(f) for f in list_inputs(path)]
    with irdic.logs.exit_on_error():
        return [str(f) for f in list_inputs(path)]


def experiment_files(kind):
    def inner(wildcards):
        return raw_files(config["experiments"][wildcards.experiment][kind]["path"])

    return inner


def setup_files(wildcards):
    s = config["setups"][wildcards.setup]
    return {
        "markers": raw_files(s["markers"]["path"]),
        "target": raw_files(s["target_image"]["path"]),
    }


def source_settings(kind):
    """Params of an ingest rule: an experiment's ``dic``/``ir``/``machine`` entry without its path."""

    def inner(wildcards):
        return {k: v for k, v in config["experiments"][wildcards.experiment][kind].items() if k != "path"}

    return inner


def figure_names():
    """Figures of an experiment: the strain and load figures need the fields rule (fields.zarr)."""
    return [n for n in irdic.plot.FIGURES if n not in ("strain", "load") or workflow.is_rule("fields")]


def experiment_results(wildcards):
    """points.zarr of an experiment, and fields.zarr when the workflow has a fields rule."""
    out = {"points": f"{RESULTS}/{wildcards.experiment}/points.zarr"}
    if workflow.is_rule("fields"):
        out["fields"] = f"{RESULTS}/{wildcards.experiment}/fields.zarr"
    return out


def export_inputs(wildcards):
    """experiment_results, and heat.zarr when the workflow has a heat rule and the experiment a material block."""
    out = experiment_results(wildcards)
    if workflow.is_rule("heat") and wildcards.experiment in heat_experiments():
        out["heat"] = f"{RESULTS}/{wildcards.experiment}/heat.zarr"
    return out


def fields_inputs(wildcards):
    """points.zarr, calibration, dic.zarr (its signals) and machine.zarr when the experiment has a machine record."""
    e = config["experiments"][wildcards.experiment]
    out = {
        "points": f"{RESULTS}/{wildcards.experiment}/points.zarr",
        "calibration": f"{RESULTS}/setups/{e['setup']}/calibration.zarr",
        "dic": f"{RESULTS}/{wildcards.experiment}/dic.zarr",
    }
    if e.get("machine"):
        out["machine"] = f"{RESULTS}/{wildcards.experiment}/machine.zarr"
    return out


def report_figures():
    """Every PNG the HTML page (the report_html rule) shows: calibrations, then each experiment's figures."""
    out = [f"{RESULTS}/setups/{s}/calibration.png" for s in SETUPS]
    for e in EXPERIMENTS:
        out += [f"{RESULTS}/{e}/figures/{name}.png" for name in figure_names()]
        if e in heat_experiments() and workflow.is_rule("heat"):
            out.append(f"{RESULTS}/{e}/figures/heat.png")
    return out


def heat_experiments():
    """The experiments with a material block: the heat rule runs for them (heat.zarr)."""
    return [e for e in EXPERIMENTS if config["experiments"][e].get("material")]


def report_stores():
    """The stores whose ``auto`` choices the page's header lists: calibrations and fields."""
    out = [f"{RESULTS}/setups/{s}/calibration.zarr" for s in SETUPS]
    if workflow.is_rule("fields"):
        out += [f"{RESULTS}/{e}/fields.zarr" for e in EXPERIMENTS]
    return out


def all_outputs():
    out = [f"{RESULTS}/setups/{s}/calibration.zarr" for s in SETUPS]
    for e in EXPERIMENTS:
        out += [f"{RESULTS}/{e}/dic.zarr", f"{RESULTS}/{e}/ir.zarr", f"{RESULTS}/{e}/points.zarr", f"{RESULTS}/{e}/fields.zarr"]
        if config["experiments"][e].get("machine"):
            out.append(f"{RESULTS}/{e}/machine.zarr")
        out += [f"{RESULTS}/{e}/figures/{name}.png" for name in figure_names()]
        out += [f"{RESULTS}/{e}/paraview", f"{RESULTS}/{e}/points.csv"]
        if e in heat_experiments():
            out += [f"{RESULTS}/{e}/heat.zarr", f"{RESULTS}/{e}/figures/heat.png"]
    out.append(f"{RESULTS}/report.html")
    return out


def planned_chunks(experiment):
    """Time chunks of an experiment's couple and fields (execution.chunk_frames), planned before ingest.

    The DIC times are counted as the DIC export files (one per stage), or
    from the demo's plan; the chunk jobs split the ingested times by position
    (irdic.chunks), so a count that differs a little still covers every time.
    """
    frames = config["execution"]["chunk_frames"]
    if frames == 0:
        return 1
    path = config["experiments"][experiment]["dic"]["path"]
    if _in_demo(path):
        name = os.path.relpath(path, DEMO["outdir"]).split(os.sep)[0]
        n = demo_stages(name, DEMO["scale"]) or 1
    else:
        with irdic.logs.exit_on_error():
            n = len(list_inputs(path))
    return irdic.chunks.n_chunks(n, frames)


def chunk_stores(kind):
    """The chunk stores (``chunks/<kind>-<i>.zarr``) an experiment's gather step reads."""

    def inner(wildcards):
        n = planned_chunks(wildcards.experiment)
        return [f"{RESULTS}/{wildcards.experiment}/chunks/{kind}-{i}.zarr" for i in range(n)]

    return inner


def couple_inputs(wildcards):
    """couple: the chunk stores when the experiment is chunked, else dic, ir and calibration."""
    if planned_chunks(wildcards.experiment) > 1:
        return {"chunks": chunk_stores("points")(wildcards)}
    return couple_chunk_inputs(wildcards)


def couple_chunk_inputs(wildcards):
    e = config["experiments"][wildcards.experiment]
    return {
        "dic": f"{RESULTS}/{wildcards.experiment}/dic.zarr",
        "ir": f"{RESULTS}/{wildcards.experiment}/ir.zarr",
        "calibration": f"{RESULTS}/setups/{e['setup']}/calibration.zarr",
    }


def fields_gather_inputs(wildcards):
    """fields: the chunk stores when the experiment is chunked, else the inputs of a whole-record run."""
    if planned_chunks(wildcards.experiment) > 1:
        return {"chunks": chunk_stores("fields")(wildcards)}
    return fields_inputs(wildcards)


def chunk_of(wildcards):
    return [int(wildcards.i), planned_chunks(wildcards.experiment)]
