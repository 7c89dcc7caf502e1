"""Values a decoded signal can take beside numbers (kept free of the native module, which
creates them)."""

from __future__ import annotations

from typing import Any


class NamedSignalValue(str):
    """A raw value with its description (a DBC's ``VAL_``), as cantools' class of that name:
    ``name`` the description, ``value`` the raw number, equal to its name as a string.

    It is a ``str`` (its name), so that cantools takes it wherever it takes a choice's name
    and cantools' own ``NamedSignalValue`` compares equal to it both ways: ``cantools_value ==
    bywire_value`` and ``bywire_dict == cantools_dict`` hold when the names are equal."""

    value: int
    name: str
    _comments: dict[str | None, str]

    def __new__(cls, value: int, name: str, comments: dict[str | None, str] | None = None) -> NamedSignalValue:
        self = super().__new__(cls, name)
        self.value = value
        self.name = name
        self._comments = comments or {}
        return self

    @property
    def comments(self) -> dict[str | None, str]:
        """The value's descriptions by language (ARXML gives several)."""
        return self._comments

    def __str__(self) -> str:
        return self.name

    def __repr__(self) -> str:
        return f"'{self.name}'"

    def __eq__(self, other: object) -> bool:
        number = getattr(other, "value", None)
        if not isinstance(other, str) or isinstance(other, NamedSignalValue):
            # Ours or cantools' class: the number and the name.
            name = getattr(other, "name", None)
            return name is not None and number == self.value and name == self.name
        return str.__eq__(self, other)

    def __ne__(self, other: object) -> bool:
        return not self.__eq__(other)

    __hash__ = str.__hash__

    def __reduce__(self) -> tuple[Any, ...]:
        return (NamedSignalValue, (self.value, self.name, self._comments or None))
