"""Snakemake job `gather` of an adaptive map: every map's rounds -> results/<name>/cube.nc on the full lattice."""
import json

from sweep import adaptive, batch

batch.setup_logging(snakemake.log[0])  # noqa: F821 (injected by Snakemake)
adaptive.gather(
    settings=json.loads(snakemake.params.settings),  # noqa: F821
    results=snakemake.output[0].rsplit("/", 1)[0],  # noqa: F821
    out_path=snakemake.output[0],  # noqa: F821
    repo_path=snakemake.scriptdir,  # noqa: F821
    name=snakemake.params.name,  # noqa: F821
)
