"""Snakemake job `notebook`: execute a notebook against the cube; it writes its figure."""
from sweep import io

io.run_notebook(
    notebook=snakemake.input.notebook,  # noqa: F821 (injected by Snakemake)
    cube=snakemake.input.cube,  # noqa: F821
    figure=snakemake.output.figure,  # noqa: F821
    executed=snakemake.output.executed,  # noqa: F821
    log_path=snakemake.log[0],  # noqa: F821
)
