# Config validation and the chunk plan, shared by every rule.
import os
import sys

from sweep import chunkfiles as sweep_chunkfiles
from sweep import chunking as sweep_chunking
from sweep import grid as sweep_grid
from sweep import validation as sweep_validation
from sweep import verify as sweep_verify


# The config is read from its files by sweep.grid (the code `python3 run.py sweep` runs before
# Snakemake starts, so both report alike): config/config.yaml, then each --configfile, merged as
# Snakemake merges them, then --config; numbers as YAML 1.2 reads them (1e-10 is a number, a
# number in quotes is text), every problem one line naming its file, key, value and allowed
# range, including the rules JSON schema cannot express (mu_d <= mu_s, alpha0 != 0, finite
# numbers, dt for the fixed step) and the physics core's own scene checks. The sweep's name,
# hence its folder results/<name>/, is the `name:` of the config file given last, else its stem.
_CONFIGFILES = [] if workflow.config_settings.replace_workflow_config else [DEFAULT_CONFIGFILE]
_CONFIGFILES += [str(f) for f in workflow.overwrite_configfiles if str(f) not in _CONFIGFILES]
try:
    _SWEEP = sweep_grid.load_sweep([(f, f) for f in _CONFIGFILES], dict(workflow.config_settings.config) or None)
except sweep_validation.SweepConfigError as err:
    raise WorkflowError("invalid sweep configuration:\n" + str(err)) from None
SWEEP_NAME, SETTINGS = _SWEEP.name, _SWEEP.settings
# the workflow's config is the validated one, defaults filled (what the rules see)
config.clear()
config.update(_SWEEP.config, name=SWEEP_NAME)
RESULTS = f"results/{SWEEP_NAME}"

SETTINGS_JSON = sweep_chunking.canonical_json(SETTINGS)
# An adaptive map (refine:) plans its chunks round by round (workflow/rules/adaptive.smk): no
# chunk plan up front; MAPS and the last round ROUNDS fix its jobs.
ADAPTIVE = sweep_grid.is_adaptive(SETTINGS)
PLAN = {} if ADAPTIVE else sweep_chunking.plan_chunks(SETTINGS)
CHUNK_DIR = f"{RESULTS}/chunks"
if ADAPTIVE:
    from sweep import adaptive as sweep_adaptive

    MAPS = sweep_adaptive.maps(SETTINGS)
    ROUNDS = sweep_adaptive.lattice(SETTINGS).rounds
    # a round runs its chunks in its own processes; Snakemake scales this down to --cores
    # (workflow.cores raises where no --cores/--jobs is given, e.g. --unlock)
    try:
        ROUND_THREADS = max(1, min(int(workflow.cores or 1), 64))
    except WorkflowError:
        ROUND_THREADS = 1

# A damaged chunk file (truncated copy, full disk, bit rot) must be recomputed, not gathered:
# the main process verifies every existing chunk of the plan and moves damaged ones to
# <results>/chunks/quarantine/, so Snakemake sees them as missing. Jobs (remote/subprocess
# executions of this file) skip the check; a dry run only reports.
# (The executor, hence workflow.dryrun, is chosen after parsing; output_settings knows -n.)
DRYRUN = bool(getattr(workflow.output_settings, "dryrun", False) or workflow.dryrun)
if workflow.is_main_process:
    _damaged = sweep_verify.check_existing_chunks(CHUNK_DIR, PLAN, act=not DRYRUN)
    for _cid, _reason in _damaged.items():
        print(f"sweep: chunk {_cid} is damaged ({_reason}); "
              + ("a real run will quarantine and recompute it" if DRYRUN
                 else f"moved to {CHUNK_DIR}/quarantine/, it will be recomputed"),
              file=sys.stderr)
    if ADAPTIVE:
        # a chunk file of a finished round gone or damaged: the gather computes it again
        # (sweep.adaptive.load_rounds), so a finished cube is out of date and made again
        _stale = sweep_adaptive.stale_chunks(SETTINGS, RESULTS)
        for _path, _reason in sorted(_stale.items()):
            print(f"sweep: chunk {_path} of a finished round is {_reason}; "
                  + ("a real run will compute it again" if DRYRUN else "it will be computed again"),
                  file=sys.stderr)
        if _stale and not DRYRUN and os.path.exists(f"{RESULTS}/cube.nc"):
            os.remove(f"{RESULTS}/cube.nc")
    if not DRYRUN:
        # what this run will compute, for the progress line of `python3 run.py sweep`
        sweep_chunkfiles.write_plan(f"{RESULTS}/plan.json", SWEEP_NAME, PLAN,
                            sweep_adaptive.plan_info(SETTINGS, RESULTS) if ADAPTIVE else None)
