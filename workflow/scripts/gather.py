"""Snakemake job `gather`: verified chunk files -> results/cube.nc."""
import json

from sweep import batch, gather

batch.setup_logging(snakemake.log[0])  # noqa: F821 (injected by Snakemake)
gather.gather(
    chunk_paths=snakemake.input.chunks,  # noqa: F821
    settings=json.loads(snakemake.params.settings),  # noqa: F821
    out_path=snakemake.output[0],  # noqa: F821
    repo_path=snakemake.scriptdir,  # noqa: F821
    history="snakemake rule gather",
    name=snakemake.params.name,  # noqa: F821
    workers=snakemake.threads,  # noqa: F821
)
