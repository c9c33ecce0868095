# All chunk files -> results/cube.nc (CF-1.10 netCDF-4, zlib), lazily with dask.


rule gather:
    input:
        chunks=expand("results/chunks/{chunk}.nc", chunk=PLAN),
    output:
        "results/cube.nc",
    params:
        settings=SETTINGS_JSON,
    log:
        "results/logs/gather.log",
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
    script:
        "../scripts/gather.py"
