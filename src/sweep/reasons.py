"""Why a value is missing: a reason code for every NaN of the frequencies and the fits.

The cube's variables `precession_hz`, `ringing_hz` (and `ringing_ratio`), `normal_force_hz`,
`t_halt`, `t_halt_error`, `approach_exponent`, `ramp_exponent` and `ramp_exponent_error`
are NaN where the scene gave them no value. Each has a companion `<name>_flag` (CF
`flag_values`/`flag_meanings`, int8): 0 where there is a value, else the reason. The reasons are
derived here from what a scene's summary holds (the level times, the frequencies, the outcome,
t_end, whether the disk lay flat), by the rules of the physics core that produced the NaN
(core/frequency.py, core/tracking.py, core/fits.py: halt_fit, ramp_fit); the core is not
asked. Where the summary cannot tell two of the core's reasons apart, one code names both
(`no_whole_cycle_window`, `too_few_maxima`; docs/pipeline.md says which, and what the core would
have to report to separate them).

`t_level` is NaN exactly where the level was not reached (`outcome` says why the scene ended
first); its `t_level_flag` also marks the level times that are the moment the disk lay flat
(`level_crossed_lying_flat`), not a crossing of the level by the energy. Every other variable
is NaN only where the scene produced no result at all (an exception: outcome numerical_error,
t_end NaN).
"""
from __future__ import annotations

import math
from collections.abc import Mapping

# code -> (flag meaning, description); codes are stored in the cube: append, never renumber
VALUE = 0
NO_RESULT = 1
LEVEL_NOT_REACHED = 2
LEVEL_CROSSED_LYING_FLAT = 3
NO_WHOLE_CYCLE_WINDOW = 4
NO_RINGING_TONE = 5
TOO_FEW_MAXIMA = 6
FEWER_THAN_THREE_LEVELS = 7
NO_FINITE_HALT = 8
HALT_LOCATED_LYING_FLAT = 9
NO_HALT_TIME = 10
FEWER_THAN_TWO_FREQUENCIES = 11
FEWER_THAN_THREE_FREQUENCIES = 12

REASONS: dict[int, tuple[str, str]] = {
    VALUE: ("value", "the variable has a value"),
    NO_RESULT: ("no_result", "the scene produced no result (an exception; outcome numerical_error, t_end NaN)"),
    LEVEL_NOT_REACHED: ("level_not_reached", "the scene ended before reaching the level (outcome says why)"),
    LEVEL_CROSSED_LYING_FLAT: (
        "level_crossed_lying_flat",
        "the disk lay flat (face contact, the halt located there) before reaching the level: the level's time "
        "is the moment it lay flat, and no motion is left to measure a frequency on"),
    NO_WHOLE_CYCLE_WINDOW: (
        "no_whole_cycle_window",
        "the level was reached, but fewer than one whole precession cycle lies before it (since the start) or "
        "after it (before the motion ended, or before a numerical stop cut the steps: see outcome), so there is "
        "no window of whole cycles centred on it: precession_hz then comes from the whole cycle next to the "
        "level on the other side where that side has two within half of each other (precession_window -1 or +1, its error "
        "precession_hz_error), and is missing where it has fewer; the ringing needs the centred window"),
    NO_RINGING_TONE: (
        "no_ringing_tone",
        "the normal force over the level's window of whole cycles does not oscillate: its best-fitting "
        "sinusoid's amplitude is below 1e-8 of its mean"),
    TOO_FEW_MAXIMA: (
        "too_few_maxima",
        "fewer than three counted normal-force maxima up to the level, or none counted after it before the "
        "motion ended (f_hat = 2/T needs three, resolved by a later one); the summary does not tell which"),
    FEWER_THAN_THREE_LEVELS: (
        "fewer_than_three_levels", "fewer than three levels were reached: the halt fit uses the last three"),
    NO_FINITE_HALT: (
        "no_finite_halt",
        "the gaps between the last three level times do not shrink fast enough (or are not positive) for the "
        "fit to give a finite halt time, nor did the levels below the last one before stop.t_max"),
    HALT_LOCATED_LYING_FLAT: (
        "halt_located_lying_flat",
        "the disk lay flat: its halt time is the located moment of face contact, not extrapolated, so there "
        "is no fitted approach exponent and no extrapolation error (t_halt_error); the located time's own "
        "error is numerical (t_halt_numerical_error, with outputs.error_estimate)"),
    NO_HALT_TIME: ("no_halt_time", "there is no halt time (see t_halt_flag), which the ramp fit needs"),
    FEWER_THAN_TWO_FREQUENCIES: (
        "fewer_than_two_frequencies",
        "fewer than two levels before t_halt have a precession frequency: the ramp fit needs two"),
    FEWER_THAN_THREE_FREQUENCIES: (
        "fewer_than_three_frequencies",
        "only two levels before t_halt have a precession frequency: the exponent's standard error needs three"),
}

# flag variable -> (the variables it explains, the codes it can take, long_name)
FLAGS: dict[str, tuple[tuple[str, ...], tuple[int, ...], str]] = {
    # t_level has a value wherever the level was reached; its flag says what kind of time it is
    "t_level_flag": (("t_level",), (VALUE, NO_RESULT, LEVEL_NOT_REACHED, LEVEL_CROSSED_LYING_FLAT),
                     "what t_level holds: 0 the time the energy-equivalent inclination reached the level; 3 the "
                     "moment the disk lay flat (the face impact took the level's energy); else why it is missing"),
    "precession_hz_flag": (("precession_hz", "precession_hz_error", "precession_window", "precession_cycles"), (VALUE, NO_RESULT, LEVEL_NOT_REACHED, LEVEL_CROSSED_LYING_FLAT,
                                                NO_WHOLE_CYCLE_WINDOW),
                           "why precession_hz is missing (0: it has a value)"),
    "ringing_hz_flag": (("ringing_hz", "ringing_ratio"), (VALUE, NO_RESULT, LEVEL_NOT_REACHED,
                                                         LEVEL_CROSSED_LYING_FLAT, NO_WHOLE_CYCLE_WINDOW,
                                                         NO_RINGING_TONE),
                        "why ringing_hz and ringing_ratio are missing (0: they have values)"),
    "normal_force_hz_flag": (("normal_force_hz",), (VALUE, NO_RESULT, LEVEL_NOT_REACHED, LEVEL_CROSSED_LYING_FLAT,
                                                    TOO_FEW_MAXIMA),
                             "why normal_force_hz is missing (0: it has a value)"),
    "t_halt_flag": (("t_halt",), (VALUE, NO_RESULT, FEWER_THAN_THREE_LEVELS, NO_FINITE_HALT),
                    "why t_halt is missing (0: it has a value)"),
    "t_halt_error_flag": (("t_halt_error",), (VALUE, NO_RESULT, FEWER_THAN_THREE_LEVELS, NO_FINITE_HALT,
                                              HALT_LOCATED_LYING_FLAT),
                          "why t_halt_error is missing (0: it has a value)"),
    "approach_exponent_flag": (("approach_exponent",), (VALUE, NO_RESULT, FEWER_THAN_THREE_LEVELS, NO_FINITE_HALT,
                                                        HALT_LOCATED_LYING_FLAT),
                               "why approach_exponent is missing (0: it has a value)"),
    "ramp_exponent_flag": (("ramp_exponent",), (VALUE, NO_RESULT, NO_HALT_TIME, FEWER_THAN_TWO_FREQUENCIES),
                           "why ramp_exponent is missing (0: it has a value)"),
    "ramp_exponent_error_flag": (("ramp_exponent_error",), (VALUE, NO_RESULT, NO_HALT_TIME,
                                                            FEWER_THAN_TWO_FREQUENCIES, FEWER_THAN_THREE_FREQUENCIES),
                                 "why ramp_exponent_error is missing (0: it has a value)"),
}
PER_LEVEL = ("t_level_flag", "precession_hz_flag", "ringing_hz_flag", "normal_force_hz_flag")


def _nan(x) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))


def _level_reason(summary: Mapping, lv: Mapping) -> int:
    """The reason shared by every frequency of level `lv` whose value is NaN, before the
    frequency's own: no result, not reached, crossed lying flat; else 0."""
    if _nan(summary.get("t_end")):
        return NO_RESULT
    if _nan(lv.get("t")):
        return LEVEL_NOT_REACHED
    # core/tracking.halt_flat: levels not yet crossed when the disk lies flat get its time, no window
    if summary.get("lay_flat") and lv["t"] == summary["t_end"]:
        return LEVEL_CROSSED_LYING_FLAT
    return VALUE


def level_flags(summary: Mapping, lv: Mapping) -> dict[str, int]:
    """The per-level flags of level `lv` of a scene's `summary`."""
    base = _level_reason(summary, lv)
    prec = VALUE if not _nan(lv.get("precession_hz")) else (base or NO_WHOLE_CYCLE_WINDOW)
    # the ringing ratio comes from the precession's centred window: without one, the same reason
    # (a one-sided precession value has no ringing)
    one_sided = lv.get("precession_window") in (-1.0, 1.0)
    ring = VALUE if not _nan(lv.get("ringing_hz")) else (prec or (NO_WHOLE_CYCLE_WINDOW if one_sided else NO_RINGING_TONE))
    nf = VALUE if not _nan(lv.get("normal_force_hz")) else (base or TOO_FEW_MAXIMA)
    return {"t_level_flag": base, "precession_hz_flag": prec, "ringing_hz_flag": ring, "normal_force_hz_flag": nf}


def fit_flags(summary: Mapping) -> dict[str, int]:
    """The flags of the fitted numbers of a scene's `summary` (core/fits.py: halt_fit, ramp_fit)."""
    if _nan(summary.get("t_end")):
        return {k: (VALUE if not _nan(summary.get(FLAGS[k][0][0])) else NO_RESULT)
                for k in FLAGS if k not in PER_LEVEL}
    times = [lv.get("t") for lv in summary["levels"]]
    reached = sum(1 for t in times if not _nan(t))
    t_halt = summary.get("t_halt")
    halt = VALUE if not _nan(t_halt) else (FEWER_THAN_THREE_LEVELS if reached < 3 else NO_FINITE_HALT)
    if not _nan(summary.get("approach_exponent")):
        approach = VALUE
    else:
        approach = HALT_LOCATED_LYING_FLAT if summary.get("lay_flat") else (halt or NO_FINITE_HALT)
    if not _nan(summary.get("ramp_exponent")):
        ramp = VALUE
    else:
        ramp = NO_HALT_TIME if _nan(t_halt) else FEWER_THAN_TWO_FREQUENCIES
    if not _nan(summary.get("ramp_exponent_error")):
        ramp_err = VALUE
    else:
        ramp_err = ramp or FEWER_THAN_THREE_FREQUENCIES
    halt_error = VALUE if not _nan(summary.get("t_halt_error")) else (
        halt or (HALT_LOCATED_LYING_FLAT if summary.get("lay_flat") else NO_FINITE_HALT))
    return {"t_halt_flag": halt, "t_halt_error_flag": halt_error, "approach_exponent_flag": approach,
            "ramp_exponent_flag": ramp,
            "ramp_exponent_error_flag": ramp_err}


def add_flags(summary: dict) -> dict:
    """A copy of `summary` with every flag: the fits' at the top level, the frequencies' in each
    level's dict."""
    out = dict(summary)
    out["levels"] = [dict(lv, **level_flags(summary, lv)) for lv in summary["levels"]]
    out.update(fit_flags(summary))
    return out


def flag_attrs(flag: str) -> dict:
    """CF attributes of a flag variable: units, long_name, flag_values, flag_meanings and, in
    `comment`, what each meaning says."""
    import numpy as np

    _, codes, long_name = FLAGS[flag]
    return {"units": "1", "long_name": long_name,
            "flag_values": np.array(codes, dtype=np.int8),
            "flag_meanings": " ".join(REASONS[c][0] for c in codes),
            "comment": "; ".join(f"{c} {REASONS[c][0]}: {REASONS[c][1]}" for c in codes)}


def flag_of(variable: str) -> str | None:
    """The flag variable that explains `variable`'s missing values, if any."""
    for flag, (explained, _, _) in FLAGS.items():
        if variable in explained:
            return flag
    return None
