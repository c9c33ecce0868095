"""Snakemake job `simulate_cuda_<job>`: the scenes of several chunks in one GPU batch call, one chunk file each."""
from sweep import ensemble

ensemble.run_chunks_job(
    specs=list(snakemake.params.specs),  # noqa: F821 (injected by Snakemake)
    expected_ids=list(snakemake.params.ids),  # noqa: F821
    out_paths=list(snakemake.output),  # noqa: F821
    log_path=snakemake.log[0],  # noqa: F821
    device="cuda",
)
