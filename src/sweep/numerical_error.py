"""The numerical error estimate of a sweep (outputs.error_estimate: true).

Every scene is rerun with the tolerances of `error_reference` (rtol and atol / 100, twice the step
budget); each output marked numerical_error=True (sweep.outputs) gets the variable
<name>_numerical_error, |value - the rerun's value| in the output's units, and `reference_outcome`
says how the rerun ended.
"""
from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import Any

from . import outcomes
from .outputs import VARIABLES, Var

# outputs.error_estimate: every scene is rerun with rtol and atol divided by this factor (not below
# the smallest tolerances the core accepts) and the step budget multiplied by ERROR_STEPS_FACTOR
# (DOP853 is 8th order: 100x tighter tolerances cost ~100^(1/8) = 1.8x the steps).
ERROR_TOL_FACTOR = 100.0
ERROR_RTOL_MIN = 1.0e-14
ERROR_ATOL_MIN = 1.0e-16
ERROR_STEPS_FACTOR = 2


def error_reference(settings_part: Mapping) -> dict:
    """The scene settings (as sweep.chunking.scene_settings returns them) of the rerun behind the error bars:
    rtol/100 (>= 1e-14), atol/100 (>= 1e-16), twice the step budget (<= 1e9); the rest alike."""
    ref = copy.deepcopy(dict(settings_part))
    so, stop = dict(ref["solver"]), dict(ref["stop"])
    so["rtol"] = max(float(so["rtol"]) / ERROR_TOL_FACTOR, ERROR_RTOL_MIN)
    so["atol"] = max(float(so["atol"]) / ERROR_TOL_FACTOR, ERROR_ATOL_MIN)
    stop["max_steps"] = min(int(stop["max_steps"]) * ERROR_STEPS_FACTOR, 1_000_000_000)
    ref["solver"], ref["stop"] = so, stop
    return ref


# the suffix of the error variable of each output marked numerical_error=True
ERROR_SUFFIX = "_numerical_error"
# Reference outcomes that mean the rerun could not get where the main run got (not a physical end):
# a value the main run has but such a rerun lacks has an unknown error (NaN), not an infinite one.
REFERENCE_FAILURES = frozenset({outcomes.STEP_LIMIT, outcomes.STEP_SIZE_UNDERFLOW, outcomes.NUMERICAL_ERROR,
                                outcomes.NOT_RUN})


def _error_var(var: Var) -> Var:
    key = var.name + ERROR_SUFFIX
    return Var(key, "float", var.units,
               f"{var.long_name}: absolute difference to a rerun at rtol/100 (numerical error estimate; "
               "NaN where there is no value or the rerun failed, inf where only this run has a value)",
               (lambda d: d[key]), per_level=var.per_level)


ERROR_VARIABLES: tuple[Var, ...] = tuple(_error_var(v) for v in VARIABLES if v.numerical_error) + (
    Var("reference_outcome", "outcome", "1",
        "outcome of the rerun at rtol/100 that gives the *_numerical_error variables (see flag_meanings)",
        lambda s: s["reference_outcome"]),
)


def _abs_difference(value: Any, ref: Any, ref_failed: bool) -> float:
    a = math.nan if value is None else float(value)
    b = math.nan if ref is None else float(ref)
    if math.isnan(a):
        return math.nan              # no value, no error bar
    if math.isnan(b):
        return math.nan if ref_failed else math.inf   # the tighter run has no such value
    return abs(a - b)


def add_numerical_errors(summary: dict, reference: Mapping | None) -> dict:
    """Add `<name>_numerical_error` (|value - reference value|) to a scene's summary, in place,
    for every variable marked numerical_error, and `reference_outcome`.

    `reference`: the summary of the same scene rerun at tighter tolerances, or None where the
    rerun raised (then every error is NaN and reference_outcome is numerical_error). A value the
    reference lacks has error inf if the rerun ended physically (the value is a numerical
    artefact), NaN if it ended in a numerical failure (step limit, underflow, error). Whole-run
    totals (counts, slip_fraction) get NaN where the rerun failed: its totals stop at its failure.
    """
    ref_code = outcomes.NUMERICAL_ERROR if reference is None else int(reference["outcome_code"])
    failed = reference is None or ref_code in REFERENCE_FAILURES
    summary["reference_outcome"] = ref_code
    for var in VARIABLES:
        if not var.numerical_error:
            continue
        key = var.name + ERROR_SUFFIX
        if var.per_level:
            for j, lv in enumerate(summary["levels"]):
                ref = var.get(reference["levels"][j]) if reference is not None else None
                lv[key] = _abs_difference(var.get(lv), ref, failed)
        elif var.whole_run and failed:
            summary[key] = math.nan    # a rerun that did not end physically has partial totals
        else:
            summary[key] = _abs_difference(var.get(summary), var.get(reference) if reference is not None else None,
                                           failed)
    return summary
