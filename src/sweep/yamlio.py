"""YAML numbers as people write them: `1e-10` is a float, not the string YAML 1.1 makes of it.

PyYAML implements YAML 1.1, whose float pattern needs a '.' and a signed exponent, so `1e-10`,
`1e6` and `2E+3` load as strings. YAML 1.2 (and every other tool a user is likely to compare
with: JSON, Python, numpy) reads them as numbers. `load` and `load_file` read scene files and
sweep config files alike with the YAML 1.2 float pattern added: one rule for numbers everywhere,
a number is written without quotes (`1e-10`, `0.5`), and a number in quotes (`'1e-10'`) is text,
rejected where a number is expected ("remove the quotes", sweep.errors).
"""
from __future__ import annotations

import re
from typing import Any

import yaml

# YAML 1.2 (core schema) floats that YAML 1.1 leaves as strings: an exponent without a '.'
# or without a sign. (Forms YAML 1.1 already reads as floats are matched by its own resolver.)
EXP_FLOAT = re.compile(r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)[eE][-+]?[0-9]+$")


class Loader(yaml.SafeLoader):
    """yaml.SafeLoader that also reads `1e-10`, `1e6`, `2.5E3` as floats."""


Loader.add_implicit_resolver("tag:yaml.org,2002:float", EXP_FLOAT, list("-+0123456789."))


def load(text: str) -> Any:
    """yaml.safe_load with YAML 1.2 exponent floats."""
    return yaml.load(text, Loader=Loader)  # noqa: S506 (a SafeLoader subclass)


def load_file(path, allowed: str) -> dict:
    """The mapping in the YAML file `path` (read by `load`). A file that is missing, unreadable,
    not YAML, empty (no content, or only comments) or not a mapping at its top level raises
    ConfigError (field '': the file as a whole; `allowed` says what it should hold)."""
    from pathlib import Path

    from .errors import ConfigError

    p = Path(path)
    if not p.is_file():
        raise ConfigError("", None, allowed, problem="no such file" if not p.exists() else "not a file")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError("", None, allowed, problem=f"cannot be read ({exc})") from None
    try:
        data = load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        what = getattr(exc, "problem", None) or type(exc).__name__
        raise ConfigError("", None, allowed, problem=f"not valid YAML ({what}{where})") from None
    if data is None:
        raise ConfigError("", None, allowed, problem="the file is empty")
    if not isinstance(data, dict):
        raise ConfigError("", None, allowed,
                          problem=f"its top level is a {type(data).__name__}, not a mapping of keys")
    return data
