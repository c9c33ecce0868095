"""Why a value is missing (issue #43, item 4): the *_flag variables of sweep.reasons.

Unit tests build summaries that hit each reason; the kernel tests run real scenes of the default
grid that end with each kind of missing value and check every flag against the kernel's own
state, read from its buffers (the frequency windows `fq`, the levels' pending column, the
counted maxima), which the summary does not carry.
"""
from __future__ import annotations

import importlib
import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from sweep import chunkfiles, chunking, configfiles, grid, outcomes, outputs, verify
from sweep import reasons as R
from sweep.scene import load_scene

simulate_module = importlib.import_module("sweep.simulate")
NAN = math.nan


def summary(levels, t_end=20.0, lay_flat=False, t_halt=21.0, approach=2.0, ramp=1.0, ramp_err=0.01, t_halt_error=None):
    if t_halt_error is None:   # as sweep.outputs gives it: no extrapolation error for a disk that lay flat
        t_halt_error = NAN if lay_flat or t_halt != t_halt else 0.5
    return {"t_end": t_end, "lay_flat": lay_flat, "t_halt": t_halt, "t_halt_error": t_halt_error,
            "approach_exponent": approach,
            "ramp_exponent": ramp, "ramp_exponent_error": ramp_err,
            "levels": [{"inclination": 0.1 ** (j + 1), "t": t, "precession_hz": p, "ringing_hz": r,
                        "ringing_ratio": r / p if p == p and r == r else NAN, "normal_force_hz": f}
                       for j, (t, p, r, f) in enumerate(levels)]}


def test_each_level_reason():
    s = summary([(5.0, 10.0, 8.0, 20.0),        # every value
                 (12.0, NAN, NAN, 30.0),        # reached, no window of whole cycles
                 (15.0, 40.0, NAN, NAN),        # window, but no tone; too few maxima
                 (NAN, NAN, NAN, NAN)])         # not reached
    got = [R.level_flags(s, lv) for lv in s["levels"]]
    assert [g["precession_hz_flag"] for g in got] == [R.VALUE, R.NO_WHOLE_CYCLE_WINDOW, R.VALUE, R.LEVEL_NOT_REACHED]
    assert [g["ringing_hz_flag"] for g in got] == [R.VALUE, R.NO_WHOLE_CYCLE_WINDOW, R.NO_RINGING_TONE,
                                                   R.LEVEL_NOT_REACHED]
    assert [g["normal_force_hz_flag"] for g in got] == [R.VALUE, R.VALUE, R.TOO_FEW_MAXIMA, R.LEVEL_NOT_REACHED]
    # lying flat: the levels not yet crossed get the moment of face contact (= t_end), no frequencies
    flat = summary([(5.0, 10.0, 8.0, 20.0), (9.5, NAN, NAN, NAN), (11.0, NAN, NAN, NAN)], t_end=11.0, lay_flat=True)
    assert [R.level_flags(flat, lv)["precession_hz_flag"] for lv in flat["levels"]] == [
        R.VALUE, R.NO_WHOLE_CYCLE_WINDOW, R.LEVEL_CROSSED_LYING_FLAT]
    # t_level has a value at every reached level; its flag marks the one that is the moment it lay flat
    assert [R.level_flags(flat, lv)["t_level_flag"] for lv in flat["levels"]] == [
        R.VALUE, R.VALUE, R.LEVEL_CROSSED_LYING_FLAT]
    assert [g["t_level_flag"] for g in got] == [R.VALUE, R.VALUE, R.VALUE, R.LEVEL_NOT_REACHED]
    # the same level time without lying flat is a level reached by the motion
    assert R.level_flags(dict(flat, lay_flat=False), flat["levels"][2])["precession_hz_flag"] == R.NO_WHOLE_CYCLE_WINDOW
    # a one-sided precession value (no centred window): it has a value, the ringing has none for that reason
    one = dict(s["levels"][2], precession_window=-1.0)
    assert R.level_flags(s, one)["precession_hz_flag"] == R.VALUE
    assert R.level_flags(s, one)["ringing_hz_flag"] == R.NO_WHOLE_CYCLE_WINDOW
    failed = outputs.empty_summary(3)
    assert {v for lv in failed["levels"] for v in R.level_flags(failed, lv).values()} == {R.NO_RESULT}
    assert set(R.fit_flags(failed).values()) == {R.NO_RESULT}


def test_each_fit_reason():
    four = [(5.0, 10.0, 8.0, 20.0), (12.0, 30.0, 24.0, 60.0), (15.0, 90.0, 70.0, 180.0), (16.0, 300.0, 240.0, 600.0)]
    assert set(R.fit_flags(summary(four)).values()) == {R.VALUE}
    two = summary(four[:2] + [(NAN,) * 4] * 2, t_halt=NAN, approach=NAN, ramp=NAN, ramp_err=NAN)
    assert R.fit_flags(two) == {"t_halt_flag": R.FEWER_THAN_THREE_LEVELS, "t_halt_error_flag": R.FEWER_THAN_THREE_LEVELS,
                                "approach_exponent_flag": R.FEWER_THAN_THREE_LEVELS,
                                "ramp_exponent_flag": R.NO_HALT_TIME, "ramp_exponent_error_flag": R.NO_HALT_TIME}
    no_halt = summary(four, t_halt=NAN, approach=NAN, ramp=NAN, ramp_err=NAN)
    assert R.fit_flags(no_halt)["t_halt_flag"] == R.NO_FINITE_HALT
    assert R.fit_flags(no_halt)["approach_exponent_flag"] == R.NO_FINITE_HALT
    flat = summary(four, lay_flat=True, approach=NAN, ramp=NAN, ramp_err=NAN)
    # lying flat: the halt is a located time, without an extrapolation error
    assert R.fit_flags(flat) == {"t_halt_flag": R.VALUE, "t_halt_error_flag": R.HALT_LOCATED_LYING_FLAT,
                                 "approach_exponent_flag": R.HALT_LOCATED_LYING_FLAT,
                                 "ramp_exponent_flag": R.FEWER_THAN_TWO_FREQUENCIES,
                                 "ramp_exponent_error_flag": R.FEWER_THAN_TWO_FREQUENCIES}
    assert R.fit_flags(summary(four, ramp_err=NAN))["ramp_exponent_error_flag"] == R.FEWER_THAN_THREE_FREQUENCIES


def test_flag_attributes_are_cf_flags():
    for flag, (explained, codes, _) in R.FLAGS.items():
        attrs = R.flag_attrs(flag)
        assert attrs["units"] == "1" and attrs["long_name"]
        assert list(attrs["flag_values"]) == list(codes) and attrs["flag_values"].dtype == np.int8
        meanings = attrs["flag_meanings"].split()
        assert len(meanings) == len(codes) and meanings[0] == "value"
        assert all(m.replace("_", "").isalnum() for m in meanings)       # CF: blank-separated words
        for name in explained:
            assert R.flag_of(name) == flag
    # every reason is used by some flag variable, and codes are not reused
    assert {c for _, codes, _ in R.FLAGS.values() for c in codes} == set(R.REASONS)
    assert len({m for m, _ in R.REASONS.values()}) == len(R.REASONS)


# ------------------------------------------------------------------------------- real scenes

def kernel_state(scene: dict):
    """The summary of a scene and the kernel's own per-level state: whether the level's window was
    opened (crossed by the motion, not by lying flat), whole cycles before it (LW_MB), lattice
    points after it (LW_NF), pending f_hat, counted maxima at or before the level time; and
    whether a numerical stop cut the steps (EndState.cut). The buffers are those integrate.integrate
    allocates, kept here."""
    from sweep.core import frequency as F, integrate as I, layout as Y
    from sweep.core.dop853 import N_DENSE

    sc = load_scene(scene)
    y0, _ = simulate_module.initial_state(sc)
    settings, level_e = simulate_module._settings(sc), simulate_module.level_energies(sc)
    nl = len(level_e)
    levels = np.full((nl, Y.LEVEL_COLS + 1), np.nan)
    levels[:, Y.LEVEL_COLS] = 0.0
    istats, fstats = np.zeros(Y.N_ISTATS, np.int64), np.zeros(Y.N_FSTATS)
    peaks, fq = np.empty((1 << 16, Y.PEAK_COLS)), np.zeros((F.FQ_LEVEL0 + nl, F.FQ_COLS))
    y = np.zeros(Y.N_FULL)
    y[:len(y0)] = y0
    sys = Y.System(sc.params.copy(), np.zeros(Y.N_CS), I.state_size(settings), np.zeros((Y.N_WORK, Y.N_WCOLS)), istats)
    work = Y.Work(y, np.zeros((Y.N_KROWS, Y.N_FULL)), np.zeros((2 * N_DENSE, Y.N_FULL)), I.tracking_arrays())
    I.run(settings, level_e, np.zeros(0), sys, work, Y.Record(fstats, levels, np.zeros((0, Y.SAMPLE_COLS)),
                                                          np.empty((0, Y.TRAJ_COLS)), peaks, np.zeros(Y.N_FULL), fq))
    assert istats[Y.I_OVERFLOW] == 0
    tpk = peaks[:istats[Y.I_PEAKS], 0]
    state = []
    for L in range(nl):
        row = F.FQ_LEVEL0 + L
        state.append({"opened": fq[row, F.LW_TL] != 0.0, "before": fq[row, F.LW_MB], "after": fq[row, F.LW_NF],
                      "pending": levels[L, Y.LEVEL_COLS] == 1.0,
                      "maxima_before": int(np.sum(tpk <= levels[L, 0]))})
    return simulate_module.simulate(sc).summary, state, bool(work.trk.ends.cut[0])


def default_grid_scene(point):
    src = configfiles.read_config([(Path(__file__).resolve().parents[1] / "config" / "config.yaml", "config.yaml")])
    return grid.scene(grid.normalize(src.config, check_scenes=False), point)


K1, K2 = 3.755e-6, 3.004e-5
SCENES = {   # points of the default grid (mu_d, k1, k2, k3, alpha0, omega0) with missing values of each kind
    "lies flat, a window short after the level": (0.3, K1, K2, 6.0e-4, 1.4, 30.0),
    "lies flat, no whole cycle before the level": (0.2, K1, K2, 6.0e-4, 1.4, 30.0),
    "t_max before the last levels": (0.1, K1, K2, 0.0, 0.6, 30.0),
    "lies flat, f_hat without a maximum after the level": (0.4, K1, K2, 1.5e-4, 1.2, 8.0),
}


@pytest.mark.parametrize("name", sorted(SCENES))
def test_flags_agree_with_the_kernels_own_state(name):
    s, state, cut = kernel_state(default_grid_scene(SCENES[name]))
    flagged = R.add_flags(s)
    seen = set()
    for lv, st, raw in zip(flagged["levels"], state, s["levels"]):
        for var in ("precession_hz", "ringing_hz", "normal_force_hz"):
            flag = lv[f"{var}_flag"]
            assert (flag == R.VALUE) == math.isfinite(raw[var]), (var, flag, raw[var])
            seen.add(flag)
        flag = lv["precession_hz_flag"]
        if flag == R.LEVEL_NOT_REACHED:
            assert not math.isfinite(raw["t"]) and not st["opened"]
        elif flag == R.LEVEL_CROSSED_LYING_FLAT:
            assert s["lay_flat"] and math.isfinite(raw["t"]) and not st["opened"]
        # whole cycles before and after the level in the kernel's window: a centred value needs one
        # each side, a one-sided one two on its side
        before, after = st["before"], st["after"] // 16
        if flag == R.NO_WHOLE_CYCLE_WINDOW:   # no centred window (the one side's cycles too few or too
            assert st["opened"] and (min(before, after) == 0 or cut), st   # unlike), or cut
        elif flag == R.VALUE:
            assert st["opened"] and not cut and (min(before, after) >= 1 or max(before, after) >= 2), st
            assert (lv["precession_window"] == 0.0) == (min(before, after) >= 1)
        if lv["normal_force_hz_flag"] == R.TOO_FEW_MAXIMA:
            assert st["pending"] or st["maxima_before"] < 3, st
    assert seen - {R.VALUE}, "the scene has no missing value"
    # the fits' flags: 0 exactly where there is a value
    for flag, (explained, _, _) in R.FLAGS.items():
        if flag not in R.PER_LEVEL:
            assert (flagged[flag] == R.VALUE) == math.isfinite(s[explained[0]]), flag


def test_the_four_scenes_show_the_reasons_the_default_grid_has():
    """Between them, the scenes above carry every per-level reason the default sweep has (its
    cube: 186 levels crossed lying flat, 17 without a window of whole cycles, 12 not reached,
    1 f_hat without a maximum after the level)."""
    seen = set()
    for point in SCENES.values():
        s = R.add_flags(simulate_module.simulate(default_grid_scene(point)).summary)
        seen |= {v for lv in s["levels"] for k, v in lv.items() if k.endswith("_flag")}
    assert seen == {R.VALUE, R.LEVEL_NOT_REACHED, R.LEVEL_CROSSED_LYING_FLAT, R.NO_WHOLE_CYCLE_WINDOW,
                    R.TOO_FEW_MAXIMA}


def test_chunk_and_cube_carry_the_flags(tmp_path):
    """A chunk of real scenes: each flag variable is int8 with CF flag attributes, the variables
    it explains name it in `ancillary_variables`, and a flag is 0 exactly where its variables
    have values."""
    settings = grid.normalize(configfiles.read_config([(Path(__file__).resolve().parents[1] / "config" / "config.yaml",
                                                        "config.yaml")]).config, check_scenes=False)
    points = [SCENES[k] for k in sorted(SCENES)]
    cid, spec = chunking.chunk_id_of(chunking.scene_settings(settings), points)
    chunk = chunking.Chunk(cid, tuple(points), spec)
    sums = [simulate_module.simulate(grid.scene(settings, p)).summary for p in points]
    path = chunkfiles.write_chunk(chunk, sums, tmp_path / f"{cid}.nc")
    assert verify.verify_chunk(path, chunk) is None
    with xr.open_dataset(path) as ds:
        for flag, (explained, codes, _) in R.FLAGS.items():
            f = ds[flag]
            assert f.dtype == np.int8 and f.attrs["units"] == "1" and "flag_meanings" in f.attrs
            assert set(np.unique(f.values)) <= set(codes)
            for name in explained:
                assert ds[name].attrs["ancillary_variables"] == flag
                # t_level's flag also marks values: the level times that are the moment the disk lay flat
                has_value = (f.values == R.VALUE) | ((f.values == R.LEVEL_CROSSED_LYING_FLAT) & (flag == "t_level_flag"))
                np.testing.assert_array_equal(has_value, np.isfinite(ds[name].values), err_msg=name)
        assert (ds.outcome.values == outcomes.T_MAX).sum() == 1
