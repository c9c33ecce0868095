# Config validation and the chunk plan, shared by every rule.
import os
import sys

from snakemake.utils import validate

from sweep import grid as sweep_grid
from sweep import io as sweep_io


# The sweep's results folder: results/<name>/, name from the config file given last (see
# sweep.grid.sweep_name); config["name"] is set to it so the merged config agrees.
try:
    SWEEP_NAME = sweep_grid.sweep_name((list(workflow.overwrite_configfiles) or [DEFAULT_CONFIGFILE])[-1])
except sweep_grid.SweepConfigError as err:
    raise WorkflowError(str(err)) from None
config["name"] = SWEEP_NAME
RESULTS = f"results/{SWEEP_NAME}"

# Numbers written like 1e-10 (YAML 1.1, hence Snakemake's loader, reads them as strings) become
# floats where the schema expects a number, before anything validates the config.
sweep_grid.coerce_numbers(config, sweep_grid.load_schema())

# Readable messages (key, value, allowed range) and the cross-field rules JSON schema cannot
# express (mu_d <= mu_s, alpha0 != 0, finite numbers, dt for the fixed step) come first; then
# Snakemake's own validation against the same schema fills the defaults into `config`.
try:
    sweep_grid.check_config(config, sweep_grid.load_schema())
except sweep_grid.SweepConfigError as err:
    raise WorkflowError(str(err)) from None
validate(config, str(sweep_grid.SCHEMA_PATH))  # the packaged schema (sweep/schema/), absolute path

SETTINGS = sweep_grid.normalize(config, sweep_grid.load_schema())
SETTINGS_JSON = sweep_grid.canonical_json(SETTINGS)
PLAN = sweep_grid.plan_chunks(SETTINGS)
CHUNK_DIR = f"{RESULTS}/chunks"

# A damaged chunk file (truncated copy, full disk, bit rot) must be recomputed, not gathered:
# the main process verifies every existing chunk of the plan and moves damaged ones to
# <results>/chunks/quarantine/, so Snakemake sees them as missing. Jobs (remote/subprocess
# executions of this file) skip the check; a dry run only reports.
# (The executor, hence workflow.dryrun, is chosen after parsing; output_settings knows -n.)
DRYRUN = bool(getattr(workflow.output_settings, "dryrun", False) or workflow.dryrun)
if workflow.is_main_process:
    _damaged = sweep_io.check_existing_chunks(CHUNK_DIR, PLAN, act=not DRYRUN)
    for _cid, _reason in _damaged.items():
        print(f"sweep: chunk {_cid} is damaged ({_reason}); "
              + ("a real run will quarantine and recompute it" if DRYRUN
                 else f"moved to {CHUNK_DIR}/quarantine/, it will be recomputed"),
              file=sys.stderr)
    if not DRYRUN:
        # what this run will compute, for the progress line of `python3 run.py sweep`
        sweep_io.write_plan(f"{RESULTS}/plan.json", SWEEP_NAME, PLAN)
