"""The one registry of a scene's outputs: every value of the summary, with its unit, long name and
how it is taken from the kernel's outputs. The summary dict (`summary`), its template for a scene
that produced no result (`empty_summary`), the cube's variables (`sweep.outputs.VARIABLES`: units,
long names, error bars) and the chunk format that names them (`CHUNK_FORMAT`) are all generated
from OUTPUTS, so a new output is one entry here.

The summary is JSON-able and in SI units. Its layout: the top-level values; `levels`, one dict
per configured level (the entries with where="levels"); `dissipation`, the energy dissipated per
mechanism (where="dissipation"). The `*_flag` entries (why a value is missing) are derived from
the summary by sweep.reasons and are added where a chunk is written.
"""
from __future__ import annotations

import hashlib
import json
import math
from collections import namedtuple
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from . import outcomes, reasons
from .core import model
from .core.fits import D_APPROACH, D_HALT_FINITE, D_RAMP, D_RAMP_ERR, D_THALT, D_THALT_ERR
from .core.layout import (F_DIMPACT, F_E0, F_EEND, F_NFMAX, F_SLIDETIME, F_TEND, I_EVENTS, I_FLAT, I_IMPACTS,
                          I_OUTCOME, I_REJECTED, I_RHS, I_SLIDE_REJECTED, I_SLIDE_STEPS, I_STEPS, I_STICK, I_TRANS,
                          L_CYCLES, L_FHAT, L_PREC_ERR, L_PREC_SIDE, L_PRECESSION, L_RINGING, L_TAU, L_WINDOW)

# What the values are taken from: the scene (sweep.scene.Scene: chi, energy scale, levels), the
# kernel's istats, fstats, levels rows (layout.LEVEL_COLS: tau, alpha, mean dtheta/dtau, f_hat,
# ringing ratio, window cycles), end state y_end, the fits (core.fits: D_*) and the wall time (s).
Source = namedtuple("Source", "scene istats fstats lev y_end fits wall")


@dataclass(frozen=True)
class Output:
    """One value of the summary."""
    key: str                   # its key in the summary (in summary, summary["levels"][j] or summary[where])
    kind: str                  # "float" | "int" | "bool" | "outcome" (an outcome code) | "text"
    units: str
    long_name: str
    value: Callable[[Source, int], Any]   # (source, level index j, 0 for the others) -> the value
    where: str = ""            # "" (top level), "levels" (one per level) or "dissipation"
    cube: str | None = ""      # the cube's variable name ("": the key; dissipation: dissipation_<key>); None: not in the cube
    # a located time, a frequency or a whole-run total whose value the numerics can move: with
    # outputs.error_estimate the cube gets <name>_numerical_error
    numerical_error: bool = False
    # a total over the whole run (a count, a time share): its rerun value only compares where the
    # rerun ended physically (a rerun cut by its step budget counts fewer)
    whole_run: bool = False

    @property
    def per_level(self) -> bool:
        return self.where == "levels"

    @property
    def cube_name(self) -> str | None:
        if self.cube is None:
            return None
        if self.cube:
            return self.cube
        return f"dissipation_{self.key}" if self.where == "dissipation" else self.key


def _finite(x) -> float:
    x = float(x)
    return x if math.isfinite(x) else math.nan


def _i(slot: int) -> Callable[[Source, int], int]:
    return lambda s, j: int(s.istats[slot])


def _fit(slot: int) -> Callable[[Source, int], float]:
    return lambda s, j: _finite(s.fits[slot])


def _energy(value: Callable[[Source], float]) -> Callable[[Source, int], float]:
    return lambda s, j: float(value(s)) * s.scene.energy_scale


def _precession_hz(s: Source, j: int) -> float:
    # the magnitude of the mean dtheta/dt over whole precession cycles around the level / 2 pi: the
    # centred window's, else the one-sided one's (core.frequency.window_values)
    rate = s.lev[j, L_PRECESSION] if math.isfinite(s.lev[j, L_PRECESSION]) else s.lev[j, L_PREC_SIDE]
    return _finite(abs(rate) / s.scene.chi / (2.0 * math.pi))


def _fhat_per_ringing(s: Source, j: int) -> float:
    # f_hat = 2/T counts every maximum of the normal force that passes its hysteresis, so it is the
    # ringing frequency where the force has one maximum per oscillation and twice it where it has
    # two of comparable height (docs/model.md, 'Frequencies at the levels'): the ratio says which
    ringing = s.lev[j, L_RINGING] * _precession_hz(s, j)
    return _finite(s.lev[j, L_FHAT] / s.scene.chi / ringing) if ringing > 0.0 else math.nan


OUTPUTS: tuple[Output, ...] = (
    Output("outcome", "text", "", "why the integration ended (its name)",
           lambda s, j: outcomes.NAMES[int(s.istats[I_OUTCOME])], cube=None),
    Output("outcome_code", "outcome", "1", "why the integration ended (see flag_meanings)",
           lambda s, j: int(s.istats[I_OUTCOME]), cube="outcome"),
    Output("t_end", "float", "s", "simulated time at the end of the integration",
           lambda s, j: float(s.fstats[F_TEND]) * s.scene.chi),
    Output("t_halt", "float", "s", "halt time (finite-time singularity) estimated from the final ramp",
           _fit(D_THALT), numerical_error=True),
    # a disk that lay flat halted at a located event: no extrapolation, so no extrapolation error
    # (the kernel's fit gives it the location tolerance, ~1e-14 s, which no one should read as an
    # error bar); its numerical error is t_halt_numerical_error (outputs.error_estimate)
    Output("t_halt_error", "float", "s", "uncertainty of the extrapolation to the halt: t_halt minus the last "
           "level time used (NaN where the disk lay flat: that halt is located, not extrapolated)",
           lambda s, j: math.nan if s.istats[I_FLAT] else _finite(s.fits[D_THALT_ERR])),
    Output("lay_flat", "bool", "1", "whether the disk lay flat (face contact): its halt is that located time",
           lambda s, j: bool(s.istats[I_FLAT]), cube=None),
    Output("halt_finite", "bool", "1", "whether the halt time was found finite",
           lambda s, j: bool(s.fits[D_HALT_FINITE])),
    Output("approach_exponent", "float", "1", "fitted exponent p of the final approach, inclination ~ "
           "(t_halt - t)^p", _fit(D_APPROACH)),
    Output("ramp_exponent", "float", "1", "fitted exponent n of the precession ramp, Omega ~ (t_halt - t)^(-n), "
           "from the precession frequencies over whole cycles", _fit(D_RAMP)),
    Output("ramp_exponent_error", "float", "1", "standard error of the fitted ramp exponent (least-squares slope)",
           _fit(D_RAMP_ERR)),
    # per level (docs/model.md, 'Frequencies at the levels')
    Output("inclination", "float", "rad", "inclination level", lambda s, j: float(s.scene.levels[j]),
           where="levels", cube=None),
    Output("t", "float", "s", "time at which the inclination first reaches the level",
           lambda s, j: _finite(s.lev[j, L_TAU] * s.scene.chi), where="levels", cube="t_level", numerical_error=True),
    Output("precession_hz", "float", "Hz", "precession frequency at the level: mean dtheta/dt / 2 pi over up to 8 "
           "whole precession cycles centred on the level time, or over the whole cycle next to it where only one "
           "side has whole cycles (see precession_window)", _precession_hz, where="levels", numerical_error=True),
    Output("precession_hz_error", "float", "Hz", "window error of precession_hz, the bias of averaging over "
           "whole cycles (centred: Richardson's estimate from the two cycles next to the level, an upper one where "
           "the nutation modulates the rate from cycle to cycle; one-sided: the change of the rate to the next "
           "cycle)", lambda s, j: _finite(abs(s.lev[j, L_PREC_ERR]) / s.scene.chi / (2.0 * math.pi)),
           where="levels"),
    Output("precession_window", "float", "1", "window of precession_hz: 0 whole cycles centred on the level, -1 "
           "the cycles before it only, +1 after it only (NaN: no value)",
           lambda s, j: _finite(s.lev[j, L_WINDOW]), where="levels"),
    Output("precession_cycles", "float", "1", "whole precession cycles precession_hz averages over (8 at most, "
           "as many each side; 1 for a one-sided value)", lambda s, j: _finite(s.lev[j, L_CYCLES]), where="levels"),
    Output("ringing_hz", "float", "Hz", "ringing frequency at the level: dominant frequency of the normal force "
           "over the same whole precession cycles (centred windows only)",
           lambda s, j: _finite(s.lev[j, L_RINGING] * _precession_hz(s, j)), where="levels", numerical_error=True),
    Output("ringing_ratio", "float", "1", "ringing frequency / precession frequency at the level (normal-force "
           "oscillations per precession cycle)", lambda s, j: _finite(s.lev[j, L_RINGING]), where="levels"),
    Output("normal_force_hz", "float", "Hz", "paper's normal-force frequency f_hat = 2/T, T spanning the three "
           "counted normal-force maxima before the level (1 % hysteresis); it counts every maximum, so it is twice "
           "ringing_hz where the force has two per oscillation",
           lambda s, j: _finite(s.lev[j, L_FHAT] / s.scene.chi), where="levels", numerical_error=True),
    Output("normal_force_hz_per_ringing", "float", "1", "normal_force_hz / ringing_hz at the level: about 2 "
           "where f_hat counts the two maxima the normal force has per oscillation, about 1 where it counts one "
           "(NaN where either is missing)", _fhat_per_ringing, where="levels", cube=None),
    Output("normal_force_hz_max", "float", "Hz", "largest normal-force frequency f_hat over the run",
           lambda s, j: float(s.fstats[F_NFMAX]) / s.scene.chi if s.fstats[F_NFMAX] > 0.0 else math.nan, cube=None),
    # the discrete sequence can hinge on a near-tangent crossing (a slip demand or a spin that only
    # grazes its threshold: docs/pipeline.md, 'Error bars'), so the counts and the slip share get
    # error bars too: a nonzero count error marks a cell whose event sequence the numerics decide
    Output("slip_fraction", "float", "1", "fraction of the simulated time spent slipping",
           lambda s, j: float(s.fstats[F_SLIDETIME] / s.fstats[F_TEND]) if s.fstats[F_TEND] > 0 else 0.0,
           numerical_error=True, whole_run=True),
    Output("n_transitions", "int", "1", "number of roll/slip transitions", _i(I_TRANS), numerical_error=True,
           whole_run=True),
    Output("n_stick", "int", "1", "number of stick episodes", _i(I_STICK), numerical_error=True, whole_run=True),
    Output("n_impacts", "int", "1", "number of impacts (plastic contact re-establishments)", _i(I_IMPACTS),
           numerical_error=True, whole_run=True),
    Output("energy_initial", "float", "J", "initial mechanical energy", _energy(lambda s: s.fstats[F_E0])),
    Output("energy_final", "float", "J", "final mechanical energy", _energy(lambda s: s.fstats[F_EEND])),
    Output("sliding", "float", "J", "energy dissipated by sliding friction",
           _energy(lambda s: s.y_end[model.Y_DSLIDE]), where="dissipation"),
    Output("k1", "float", "J", "energy dissipated by the k1 rolling-resistance moment",
           _energy(lambda s: s.y_end[model.Y_DK1]), where="dissipation"),
    Output("k2", "float", "J", "energy dissipated by the k2 pivoting-resistance moment",
           _energy(lambda s: s.y_end[model.Y_DK2]), where="dissipation"),
    Output("k3", "float", "J", "energy dissipated by the k3 rolling-resistance moment",
           _energy(lambda s: s.y_end[model.Y_DK3]), where="dissipation"),
    Output("impact", "float", "J", "energy dissipated in impacts", _energy(lambda s: s.fstats[F_DIMPACT]),
           where="dissipation"),
    Output("n_steps", "int", "1", "number of accepted integration steps", _i(I_STEPS)),
    Output("n_rejected", "int", "1", "number of rejected integration steps", _i(I_REJECTED)),
    Output("n_steps_sliding", "int", "1", "number of accepted steps while slipping", _i(I_SLIDE_STEPS), cube=None),
    Output("n_rejected_sliding", "int", "1", "number of rejected steps while slipping", _i(I_SLIDE_REJECTED),
           cube=None),
    Output("n_rhs", "int", "1", "number of right-hand-side evaluations", _i(I_RHS)),
    Output("n_events", "int", "1", "number of located events", _i(I_EVENTS)),
    Output("wall_time", "float", "s", "wall-clock time of the integration", lambda s, j: float(s.wall)),
)

KEYS = tuple(o.key for o in OUTPUTS if o.where == "")


def _assemble(value_of: Callable[[Output, int], Any], n_levels: int) -> dict:
    """The summary's layout filled by value_of(output, j), in OUTPUTS' order (a group, `levels` or
    `dissipation`, where its first entry is)."""
    out: dict[str, Any] = {}
    for o in OUTPUTS:
        if o.where == "levels":
            levels = out.setdefault("levels", [{} for _ in range(n_levels)])
            for j in range(n_levels):
                levels[j][o.key] = value_of(o, j)
        elif o.where:
            out.setdefault(o.where, {})[o.key] = value_of(o, 0)
        else:
            out[o.key] = value_of(o, 0)
    return out


def summary(src: Source) -> dict:
    """The JSON-able summary (SI) of a scene from the kernel's outputs (src: Source)."""
    return _assemble(lambda o, j: o.value(src, j), len(src.scene.levels))


def _missing(o: Output, outcome_code: int, wall_time: float):
    if o.key == "outcome":
        return outcomes.NAMES[outcome_code]
    if o.key == "outcome_code":
        return outcome_code
    if o.key == "wall_time":
        return wall_time
    return {"float": math.nan, "int": None, "bool": False}[o.kind]


def empty_summary(n_levels: int, outcome_code: int = outcomes.NUMERICAL_ERROR, wall_time: float = math.nan) -> dict:
    """The summary of a scene that produced no result: NaN everywhere, counts missing (None)."""
    return _assemble(lambda o, j: _missing(o, outcome_code, wall_time), n_levels)


# --- the cube's variables --------------------------------------------------------------------------
@dataclass(frozen=True)
class Var:
    """One variable of a chunk file and of the cube: how to take it from a summary, and its CF metadata."""
    name: str
    kind: str                      # "float" | "int" | "bool" | "outcome" | "flag" (sweep.reasons)
    units: str
    long_name: str
    get: Callable[[Mapping], Any]  # summary -> scalar, or (for per_level) level dict -> scalar
    per_level: bool = False
    numerical_error: bool = False
    whole_run: bool = False


def _getter(o: Output) -> Callable[[Mapping], Any]:
    if o.where == "dissipation":
        return lambda s, k=o.key: s["dissipation"][k]
    return lambda d, k=o.key: d[k]


VARIABLES: tuple[Var, ...] = tuple(
    Var(o.cube_name, o.kind, o.units, o.long_name, _getter(o), o.per_level, o.numerical_error, o.whole_run)
    for o in OUTPUTS if o.cube_name is not None
) + tuple(
    # why a frequency or a fitted number is missing (sweep.reasons): int8 CF flags, 0 = has a value
    Var(flag, "flag", "1", reasons.FLAGS[flag][2],
        (lambda lv, f=flag: lv[f]) if flag in reasons.PER_LEVEL else (lambda s, f=flag: s[f]),
        per_level=flag in reasons.PER_LEVEL)
    for flag in reasons.FLAGS
)

# Bump LAYOUT when the chunk file's layout changes in a way the variables do not show; the rest of
# the chunk format is the digest of the variables themselves (names, kinds, units, per level, error
# bars, flag codes), so a new, removed or changed output gives every chunk a new identity and old
# chunk files are recomputed instead of being gathered.
LAYOUT = 3


def chunk_format(variables=VARIABLES, flags=reasons.FLAGS) -> str:
    """The chunk format's name: LAYOUT and the digest of what the chunk files hold."""
    spec = [(v.name, v.kind, v.units, v.per_level, v.numerical_error, v.whole_run) for v in variables] + [
        (flag, list(codes)) for flag, (_, codes, _) in flags.items()]
    return f"{LAYOUT}-{hashlib.sha256(json.dumps(spec).encode()).hexdigest()[:12]}"


CHUNK_FORMAT = chunk_format()
