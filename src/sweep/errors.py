"""Exceptions raised at the user-facing boundary."""


class ConfigError(ValueError):
    """An input (scene file, sweep config, CLI option) is invalid; raised before any work starts.

    The message names the field (dotted path), the offending value and the allowed range.
    """

    def __init__(self, field: str, value, allowed: str):
        self.field = field
        self.value = value
        self.allowed = allowed
        super().__init__(f"{field} = {value!r} is invalid: allowed {allowed}")
