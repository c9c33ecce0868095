# All chunk files -> results/<name>/cube.nc (CF-1.10 netCDF-4, zlib), read by `threads` processes.


rule gather:
    input:
        chunks=expand(f"{RESULTS}/chunks/{{chunk}}.nc", chunk=PLAN),
    output:
        f"{RESULTS}/cube.nc",
    params:
        settings=SETTINGS_JSON,
        name=SWEEP_NAME,
    log:
        f"{RESULTS}/logs/gather.log",
    threads: 2
    resources:
        mem_mb=4000,
        runtime=60,
    script:
        "../scripts/gather.py"
