"""Snakemake job `notebook`: execute the configured notebooks against the cube in this one process; each writes its figure."""
from sweep import notebooks

notebooks.run_notebooks(
    notebooks=snakemake.input.notebooks,  # noqa: F821 (injected by Snakemake)
    cube=snakemake.input.cube,  # noqa: F821
    figures=snakemake.output.figures,  # noqa: F821
    executed=snakemake.output.executed,  # noqa: F821
    log_path=snakemake.log[0],  # noqa: F821
)
