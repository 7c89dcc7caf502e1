"""The errors :mod:`bywire.database` raises, named and nested as cantools' ``database.errors``:
every one is a :class:`Error`; ``ParseError`` for a file that cannot be read,
``DecodeError`` and ``EncodeError`` for data and values that do not convert."""

from __future__ import annotations

from .._native import DecodeError, EncodeError, Error, ParseError

__all__ = ["DecodeError", "EncodeError", "Error", "ParseError", "UnsupportedDatabaseFormatError"]


class UnsupportedDatabaseFormatError(ParseError):
    """Text that no database format reads (a :class:`ParseError`, as cantools' is an
    :class:`Error`): the reason each format gave (``e_arxml``, ``e_dbc``, ``e_kcd``,
    ``e_sym``, ``e_cdd``)."""

    def __init__(
        self,
        e_arxml: Exception | None = None,
        e_dbc: Exception | None = None,
        e_kcd: Exception | None = None,
        e_sym: Exception | None = None,
        e_cdd: Exception | None = None,
    ) -> None:
        self.e_arxml, self.e_dbc, self.e_kcd, self.e_sym, self.e_cdd = e_arxml, e_dbc, e_kcd, e_sym, e_cdd
        reasons = [
            f"{name}: \"{error}\""
            for name, error in (("ARXML", e_arxml), ("DBC", e_dbc), ("KCD", e_kcd), ("SYM", e_sym), ("CDD", e_cdd))
            if error is not None
        ]
        super().__init__(", ".join(reasons))

    def __reduce__(self) -> tuple[type, tuple[Exception | None, ...]]:
        return (type(self), (self.e_arxml, self.e_dbc, self.e_kcd, self.e_sym, self.e_cdd))
