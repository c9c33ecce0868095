# Execute a notebook of workflow/notebooks/ against the cube; it saves results/figures/<name>.png.


rule notebook:
    input:
        cube=f"{RESULTS}/cube.nc",
        notebook=os.path.join(workflow.basedir, "workflow", "notebooks", "{notebook}.ipynb"),
    output:
        figure=f"{RESULTS}/figures/{{notebook}}.png",
        executed=f"{RESULTS}/notebooks/{{notebook}}.ipynb",
    log:
        f"{RESULTS}/logs/notebooks/{{notebook}}.log",
    wildcard_constraints:
        notebook="|".join(sweep_grid.NOTEBOOKS + sweep_grid.ADAPTIVE_NOTEBOOKS),
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    script:
        "../scripts/run_notebook.py"
