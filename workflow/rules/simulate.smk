# One job per chunk, its scenes one after another in one process, writing results/<name>/chunks/<id>.nc.


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
