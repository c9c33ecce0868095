# Euler's disk parameter sweep: config -> chunk jobs -> results/<name>/cube.nc -> figures/*.png
#
#   snakemake -j2                                  # default sweep (config/config.yaml) -> results/default/
#   snakemake -j2 --configfile config/tiny.yaml    # the CI-sized grid -> results/tiny/
#   snakemake --profile workflow/profiles/slurm    # on a SLURM cluster
#
# Each sweep writes to results/<name>/: `name:` of the config file given last (--configfile, else
# config/config.yaml), or that file's stem; so runs of different configs never mix.
# See docs/pipeline.md. All logic lives in the `sweep` package; the rules only wire files.
from snakemake.utils import min_version

min_version("9.0")


DEFAULT_CONFIGFILE = "config/config.yaml"


configfile: DEFAULT_CONFIGFILE


include: "workflow/rules/common.smk"


localrules:
    all,


rule all:
    default_target: True
    input:
        f"{RESULTS}/cube.nc",
        expand(f"{RESULTS}/figures/{{notebook}}.png", notebook=SETTINGS["outputs"]["notebooks"]),


if ADAPTIVE:

    include: "workflow/rules/adaptive.smk"

else:

    include: "workflow/rules/simulate.smk"
    include: "workflow/rules/gather.smk"


include: "workflow/rules/figures.smk"
