# Execute the configured notebooks of workflow/notebooks/ against the cube, all in one process
# (sweep.notebooks.run_notebooks: no Jupyter kernel per notebook); each saves results/<name>/figures/<name>.png
# and is kept with its outputs as results/<name>/notebooks/<name>.ipynb.

if SETTINGS["outputs"]["notebooks"]:

    rule notebook:
        input:
            cube=f"{RESULTS}/cube.nc",
            notebooks=[os.path.join(workflow.basedir, "workflow", "notebooks", f"{nb}.ipynb")
                       for nb in SETTINGS["outputs"]["notebooks"]],
        output:
            figures=[f"{RESULTS}/figures/{nb}.png" for nb in SETTINGS["outputs"]["notebooks"]],
            executed=[f"{RESULTS}/notebooks/{nb}.ipynb" for nb in SETTINGS["outputs"]["notebooks"]],
        log:
            f"{RESULTS}/logs/notebooks.log",
        threads: 1
        resources:
            mem_mb=2000,
            runtime=30,
        script:
            "../scripts/run_notebook.py"
