# An adaptive map (config `refine:`): rounds 0..R per map, one job each, chained by their round
# files; then the cube on the full lattice. sweep.adaptive has the logic (docs/pipeline.md,
# "Adaptive maps"). A round job runs its chunks in its own processes, `threads` at a time.


rule refine_round:
    input:
        lambda w: [] if int(w.k) == 0 else [f"{RESULTS}/rounds/{w.map}/round{int(w.k) - 1}.json"],
    output:
        f"{RESULTS}/rounds/{{map}}/round{{k}}.json",
    params:
        settings=SETTINGS_JSON,
        name=SWEEP_NAME,
    log:
        f"{RESULTS}/logs/rounds/{{map}}/round{{k}}.log",
    wildcard_constraints:
        map="map-[0-9a-f]{12}",
        k="[0-9]+",
    threads: ROUND_THREADS
    resources:
        mem_mb=2000,
        runtime=240,
    script:
        "../scripts/refine_round.py"


rule gather:
    input:
        [f"{RESULTS}/rounds/{m}/round{ROUNDS}.json" for m in MAPS],
    output:
        f"{RESULTS}/cube.nc",
    params:
        settings=SETTINGS_JSON,
        name=SWEEP_NAME,
    log:
        f"{RESULTS}/logs/gather.log",
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
    script:
        "../scripts/gather_adaptive.py"
