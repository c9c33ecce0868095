"""The README's paper-case table must be what `python3 run.py scene config/scenes/kessler2002.yaml
--json` prints, to the digits the table shows.

Each number in the table is compared with the computed value rounded to the printed digits
(tolerance half a unit of the last printed digit): "15.0854" must be 15.0854 +- 0.00005, "153"
must be 153 +- 0.5. When the integrator changes a figure, this test names the cell to update.
"""
from __future__ import annotations

import json
import re
import subprocess
import sys
from decimal import Decimal
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "config" / "scenes" / "kessler2002.yaml"
# table column header -> key of a level in the JSON summary
COLUMNS = {"level (rad)": "inclination", "t (s)": "t", "precession (Hz)": "precession_hz",
           "ringing (Hz)": "ringing_hz", "normal force (Hz)": "normal_force_hz"}


def readme_table(text: str) -> list[dict[str, str]]:
    """Rows of the markdown table whose header is COLUMNS, as {header: printed text}."""
    lines = text.splitlines()
    header = "| " + " | ".join(COLUMNS) + " |"
    start = [i for i, line in enumerate(lines) if line.strip() == header]
    assert len(start) == 1, f"README.md: expected one table with header {header!r}, found {len(start)}"
    rows = []
    for line in lines[start[0] + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        rows.append(dict(zip(COLUMNS, cells)))
    assert rows, "README.md: the paper-case table has no rows"
    return rows


def half_unit(printed: str) -> float:
    """Half a unit of the last printed digit: '15.0854' -> 5e-5, '153' -> 0.5, '0.1' -> 0.05."""
    return 0.5 * 10.0 ** Decimal(printed).as_tuple().exponent


def test_half_unit():
    assert half_unit("15.0854") == 5e-5 and half_unit("153") == 0.5 and half_unit("0.0001") == 5e-5


def test_readme_table_parser_finds_a_wrong_cell():
    text = ("x\n| level (rad) | t (s) | precession (Hz) | ringing (Hz) | normal force (Hz) |\n|---|---|---|---|---|\n"
            "| 0.1 | 7.2 | 14.0 | 12.3 | 23.5 |\n\nafter\n")
    rows = readme_table(text)
    assert rows == [{"level (rad)": "0.1", "t (s)": "7.2", "precession (Hz)": "14.0", "ringing (Hz)": "12.3",
                     "normal force (Hz)": "23.5"}]
    assert abs(7.1179 - float(rows[0]["t (s)"])) > half_unit(rows[0]["t (s)"])


@pytest.fixture(scope="module")
def scene_json():
    out = subprocess.run([sys.executable, "-m", "sweep", "scene", str(SCENE), "--json"], cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout)


def test_readme_paper_case_summary_line_matches_scene_json(scene_json):
    """The prose under the table: halt time and its error, ramp exponent, largest normal-force
    frequency, slip fraction to the printed digits; the event counts exactly; steps and right-hand
    side evaluations to 2 % (they follow the floating-point details of the platform)."""
    text = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    m = re.search(r"t_halt = ([0-9.]+) ± ([0-9.]+) s \(finite\), ramp exponent ([0-9.]+) ± ([0-9.]+), maximum "
                  r"normal-force frequency ([0-9]+) Hz, slip fraction ([0-9.]+), ([0-9]+) roll↔slip transitions, "
                  r"([0-9]+) stick phases; ([0-9 ]+) steps, ([0-9 ]+) right-hand-side evaluations", text)
    assert m, "README.md: the paper-case summary line is missing or reworded"
    s = scene_json
    for printed, value in zip(m.groups()[:6], (s["t_halt"], s["t_halt_error"], s["ramp_exponent"],
                                               s["ramp_exponent_error"], s["normal_force_hz_max"],
                                               s["slip_fraction"])):
        assert abs(value - float(printed)) <= half_unit(printed) * (1 + 1e-9), (printed, value)
    assert (int(m.group(7)), int(m.group(8))) == (s["n_transitions"], s["n_stick"])
    for printed, value in ((m.group(9), s["n_steps"]), (m.group(10), s["n_rhs"])):
        assert abs(int(printed.replace(" ", "")) - value) <= 0.02 * value, (printed, value)


def test_readme_paper_case_table_matches_scene_json(scene_json):
    rows = readme_table((ROOT / "README.md").read_text(encoding="utf-8"))
    levels = scene_json["levels"]
    assert len(rows) == len(levels), (f"README.md has {len(rows)} rows, `scene --json` reports "
                                      f"{len(levels)} levels")
    wrong = []
    for row, level in zip(rows, levels):
        for header, key in COLUMNS.items():
            printed, value = row[header], level[key]
            if value is None or abs(value - float(printed)) > half_unit(printed) * (1 + 1e-9):
                digits = max(0, -Decimal(printed).as_tuple().exponent)
                wrong.append(f"level {row['level (rad)']}, {header}: README {printed}, "
                             f"scene --json {value if value is None else f'{value:.{digits}f}'} ({value!r})")
    assert not wrong, ("README.md's paper-case table no longer matches "
                       "`python3 run.py scene config/scenes/kessler2002.yaml --json`:\n  " + "\n  ".join(wrong))
