"""Snakemake job `simulate_chunk`: integrate one chunk's scenes and write its chunk file."""
from sweep import batch

batch.run_chunk_job(
    spec_json=snakemake.params.spec,  # noqa: F821 (injected by Snakemake)
    expected_id=snakemake.wildcards.chunk,  # noqa: F821
    out_path=snakemake.output[0],  # noqa: F821
    log_path=snakemake.log[0],  # noqa: F821
)
