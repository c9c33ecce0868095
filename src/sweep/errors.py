"""Exceptions raised at the user-facing boundary, and the one line each invalid input gets.

Scene files, sweep configs and command-line options are reported alike, one line per invalid
field, naming the file (where there is one), the field (dotted path), the value and what is
allowed:

    config/scenes/my.yaml: contact.mu_d = 0.9 is invalid: exceeds mu_s = 0.5; allowed [0, mu_s] = [0, 0.5] (...)
    my_sweep.yaml: chunk_sise = 3 is invalid: no such key; allowed keys: chunk_size, disk, ...
    my_sweep.yaml: grid.k2 is missing: a required key; allowed ...
    empty.yaml: the file is empty; allowed a YAML mapping ...
"""
from __future__ import annotations


class _Missing:
    """The value of a required key that is absent."""

    def __repr__(self) -> str:
        return "<missing>"


MISSING = _Missing()


def quoted_number(value) -> bool:
    """Whether `value` is text that reads as a number ('1e-10', "0.5"): a number in quotes."""
    if not isinstance(value, str):
        return False
    try:
        float(value.strip())
    except ValueError:
        return False
    return value.strip().lower() not in {"nan", "inf", "-inf", "+inf", "infinity", "-infinity"}


QUOTED_HINT = "a number in quotes is text: remove the quotes"


class ConfigError(ValueError):
    """An input (scene file, sweep config, CLI option) is invalid; raised before any work starts.

    The message names the field (dotted path), the offending value and the allowed range;
    `problem` says what is wrong where the value alone does not (an unknown key, a duplicate),
    `source` names the file the value came from (set by whoever read the file).
    """

    def __init__(self, field: str, value, allowed: str, problem: str | None = None,
                 source: str | None = None):
        self.field = field
        self.value = value
        self.allowed = allowed
        if problem is None and quoted_number(value):
            problem = QUOTED_HINT
        self.problem = problem
        self.source = source
        super().__init__(self.line())

    def line(self) -> str:
        """The one-line message: `[source: ]field = value is invalid: [problem; ]allowed ...`."""
        where = f"{self.source}: " if self.source else ""
        if not self.field:      # the file as a whole (missing, empty, not YAML)
            return f"{where}{self.problem}; allowed {self.allowed}"
        if self.value is MISSING:
            return f"{where}{self.field} is missing: {self.problem or 'a required key'}; allowed {self.allowed}"
        problem = f"{self.problem}; " if self.problem else ""
        return f"{where}{self.field} = {self.value!r} is invalid: {problem}allowed {self.allowed}"

    def with_source(self, source: str | None) -> "ConfigError":
        """This error, naming the file `source` (the first source given wins)."""
        if source and not self.source:
            self.source = source
            self.args = (self.line(),)
        return self

    def lines(self) -> list[str]:
        """The message, one line per invalid field (here: one)."""
        return [self.line()]

    def __str__(self) -> str:
        return self.line()


class ConfigErrors(ConfigError):
    """Several invalid fields of one input (a scene file), all reported at once: `errors`, one
    ConfigError per field, in the order found. It is a ConfigError (its field, value and allowed
    range those of the first), so a caller that handles one handles all; `lines()` gives each
    field's line."""

    def __init__(self, errors):
        self.errors = list(errors)
        first = self.errors[0]
        super().__init__(first.field, first.value, first.allowed, problem=first.problem, source=first.source)
        self.args = ("\n".join(self.lines()),)

    def lines(self) -> list[str]:
        return [e.line() for e in self.errors]

    def with_source(self, source: str | None) -> "ConfigErrors":
        for e in self.errors:
            e.with_source(source)
        super().with_source(source)
        self.args = ("\n".join(self.lines()),)
        return self

    def __str__(self) -> str:
        return "\n".join(self.lines())


def raise_all(errors) -> None:
    """Raise the errors collected (one: itself; several: ConfigErrors), if any."""
    errors = list(errors)
    if len(errors) == 1:
        raise errors[0]
    if errors:
        raise ConfigErrors(errors)
