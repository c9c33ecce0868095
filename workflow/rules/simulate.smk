# Device cpu (execution.device, the default): one job per chunk, its scenes one after another in one
# process, writing results/chunks/<id>.nc.
# Device cuda: one job per GPU batch of consecutive chunks (at most execution.chunk_size scenes in all),
# one sweep.simulate_batch call on the GPU, writing every chunk file of the batch; `resources: gpu=1`
# lets `--resources gpu=1` (one GPU on this machine) schedule it, and the SLURM executor plugin turns
# it into `sbatch --gpus=1`. The chunk files, their ids and the cube are the same whichever device made them.

DEVICE = SETTINGS["execution"]["device"]

if DEVICE == "cpu":

    rule simulate_chunk:
        output:
            f"{RESULTS}/chunks/{{chunk}}.nc",
        params:
            # the chunk's canonical JSON; its SHA-256 is the chunk id, so a change of any value
            # or setting gives a new id (and a new job) rather than a silent overwrite
            spec=lambda wildcards: PLAN[wildcards.chunk].spec_json,
        log:
            f"{RESULTS}/logs/chunks/{{chunk}}.log",
        wildcard_constraints:
            chunk="[0-9a-f]{16}",
        threads: 1
        resources:
            mem_mb=1000,
            runtime=60,
        script:
            "../scripts/simulate_chunk.py"

else:
    DEVICE_JOBS = sweep_grid.plan_device_jobs(PLAN, SETTINGS["execution"]["chunk_size"])

    for _job, _ids in DEVICE_JOBS.items():

        rule:
            name:
                f"simulate_cuda_{_job}"
            output:
                [f"{RESULTS}/chunks/{c}.nc" for c in _ids],
            params:
                ids=list(_ids),
                specs=[PLAN[c].spec_json for c in _ids],
            log:
                f"{RESULTS}/logs/cuda/{_job}.log",
            threads: 1
            resources:
                gpu=1,
                mem_mb=16000,
                runtime=240,
            script:
                "../scripts/simulate_cuda.py"
