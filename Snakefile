# Euler's disk parameter sweep: config -> chunk jobs -> results/cube.nc -> results/figures/*.png
#
#   snakemake -j2                                  # default sweep (config/config.yaml)
#   snakemake -j2 --configfile config/tiny.yaml    # the CI-sized grid
#   snakemake --profile workflow/profiles/slurm    # on a SLURM cluster
#
# See docs/pipeline.md. All logic lives in the `sweep` package; the rules only wire files.
from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


include: "workflow/rules/common.smk"


localrules:
    all,


rule all:
    default_target: True
    input:
        "results/cube.nc",
        expand("results/figures/{notebook}.png", notebook=SETTINGS["outputs"]["notebooks"]),


include: "workflow/rules/simulate.smk"
include: "workflow/rules/gather.smk"
include: "workflow/rules/figures.smk"
