"""Snakemake job `refine_round`: plan one round of an adaptive map, run its chunks, write its round file."""
import json

from sweep import adaptive, batch

batch.setup_logging(snakemake.log[0])  # noqa: F821 (injected by Snakemake)
adaptive.run_round(
    settings=json.loads(snakemake.params.settings),  # noqa: F821
    map_id=snakemake.wildcards.map,  # noqa: F821
    k=int(snakemake.wildcards.k),  # noqa: F821
    results=snakemake.output[0].rsplit("/rounds/", 1)[0],  # noqa: F821
    out_path=snakemake.output[0],  # noqa: F821
    threads=snakemake.threads,  # noqa: F821
    name=snakemake.params.name,  # noqa: F821
)
