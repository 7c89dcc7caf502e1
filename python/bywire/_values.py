"""Values a decoded signal can take beside numbers (kept free of the native module, which
creates them)."""

from __future__ import annotations


class NamedSignalValue:
    """A raw value with its description (a DBC's ``VAL_``), as cantools' class of that name:
    equal to its name as a string, ``value`` the raw number."""

    __slots__ = ("value", "name")

    def __init__(self, value: int, name: str) -> None:
        self.value = value
        self.name = name

    def __str__(self) -> str:
        return self.name

    def __repr__(self) -> str:
        return f"'{self.name}'"

    def __eq__(self, other: object) -> bool:
        if isinstance(other, str):
            return other == self.name
        if isinstance(other, NamedSignalValue):
            return other.value == self.value and other.name == self.name
        # cantools' class (or any with value and name) compares by both.
        value, name = getattr(other, "value", None), getattr(other, "name", None)
        if name is not None:
            return value == self.value and name == self.name
        return False

    def __hash__(self) -> int:
        return hash(self.name)
