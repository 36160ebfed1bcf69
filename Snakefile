# irdic: couple stereo DIC and infrared thermography, stage by stage.
# Rules live in workflow/rules/, logic in the irdic package, settings in config/.

from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/demo.smk"
include: "workflow/rules/ingest.smk"
include: "workflow/rules/calibrate.smk"
include: "workflow/rules/couple.smk"
include: "workflow/rules/fields.smk"
include: "workflow/rules/heat.smk"
include: "workflow/rules/report.smk"


rule all:
    input:
        all_outputs(),
    default_target: True
