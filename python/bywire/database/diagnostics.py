"""Diagnostic databases (CANdela CDD) as cantools' ``cantools.database.diagnostics`` gives
them: the DIDs an ECU answers with, each record decoded and encoded field by field by the
codec every frame uses."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

from ._objects import Message, Signal

__all__ = ["Data", "Database", "Did"]

#: A DID's field: a signal of the DID's record.
Data = Signal


class Did:
    """A data identifier: its identifier, name, record length and fields (``datas``)."""

    def __init__(self, message: Message) -> None:
        self._message = message

    @property
    def identifier(self) -> int:
        return self._message.frame_id

    @property
    def name(self) -> str:
        return self._message.name

    @property
    def length(self) -> int:
        return self._message.length

    @property
    def datas(self) -> list[Signal]:
        return self._message.signals

    def get_data_by_name(self, name: str) -> Signal:
        for data in self.datas:
            if data.name == name:
                return data
        raise KeyError(name)

    def decode(
        self,
        data: bytes,
        decode_choices: bool = True,
        scaling: bool = True,
        allow_truncated: bool = False,
        allow_excess: bool = True,
    ) -> dict[str, Any]:
        """The record's fields: ``{name: value}``, value names as cantools gives them."""
        return self._message.decode(data[: self.length], decode_choices, scaling, False, allow_truncated, allow_excess)

    def encode(self, data: Mapping[str, Any], scaling: bool = True) -> bytes:
        """The record of these field values."""
        return self._message.encode(data, scaling, False, False)

    def __repr__(self) -> str:
        return f"did('{self.name}', 0x{self.identifier:04x})"


class Database:
    """The DIDs of a diagnostic description."""

    def __init__(self, dids: list[Did] | None = None) -> None:
        self._dids = list(dids or [])

    @property
    def dids(self) -> list[Did]:
        return self._dids

    def get_did_by_name(self, name: str) -> Did:
        for did in self._dids:
            if did.name == name:
                return did
        raise KeyError(name)

    def get_did_by_identifier(self, identifier: int) -> Did:
        for did in self._dids:
            if did.identifier == identifier:
                return did
        raise KeyError(identifier)

    def __repr__(self) -> str:
        return "\n".join(repr(d) for d in self._dids)


def load_file(filename: str | os.PathLike[str]) -> Database:
    """Load a CDD file's DIDs."""
    from . import load_file as load_any

    return load_any(filename, database_format="cdd")  # type: ignore[return-value]
