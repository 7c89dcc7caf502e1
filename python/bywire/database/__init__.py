"""CAN databases shaped like ``cantools.database``: ``load_file``, ``load_string``, ``load``,
``dump_file``, and ``Database``, ``Message``, ``Signal``, ``Node`` with cantools' names,
arguments and meanings, read by bywire's own readers (DBC, KCD, SYM, ARXML) and decoded and encoded
natively. A cantools user changes the import::

    import bywire.database as database   # was: import cantools.database as database
    db = database.load_file("vehicle.dbc")
    message = db.get_message_by_name("VehicleToAds_State")
    print(message.decode(payload))

The departures from cantools are listed in the package's README ("Migrating from cantools")."""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping
from typing import IO, Any

from .. import _native
from .._values import NamedSignalValue
from . import errors
from ._objects import (
    SORT_SIGNALS_DEFAULT,
    Attribute,
    AttributeDefinition,
    Bus,
    Conversion,
    DbcSpecifics,
    Message,
    Node,
    Signal,
    _attribute,
    _native_of,
    _refuse_layout,
    sort_signals_by_name,
    sort_signals_by_start_bit,
    start_bit,
)
from .errors import DecodeError, EncodeError, Error, ParseError, UnsupportedDatabaseFormatError

__all__ = [
    "Attribute",
    "AttributeDefinition",
    "Bus",
    "Conversion",
    "Database",
    "DbcSpecifics",
    "DecodeError",
    "EncodeError",
    "Error",
    "Message",
    "NamedSignalValue",
    "Node",
    "ParseError",
    "Signal",
    "UnsupportedDatabaseFormatError",
    "dump_file",
    "load",
    "load_file",
    "load_string",
    "sort_signals_by_name",
    "sort_signals_by_start_bit",
]

#: The formats read (a CDD loads as a diagnostic database of DIDs, as in cantools).
FORMATS = ("dbc", "kcd", "sym", "arxml", "cdd")
_ALL_MASK = 0xFFFFFFFF
_EXTENDED = 0x80000000


def sort_signals_by_start_bit_reversed(signals: list[Signal]) -> list[Signal]:
    return sorted(signals, key=start_bit)[::-1]


class Database:
    """A CAN database: ``messages``, ``nodes``, ``buses``, ``version``, ``dbc``; lookups by
    name and frame identifier; ``decode_message``/``encode_message`` as cantools has them
    (natively, cantools' order of signals in a decoded dict); ``as_dbc_string``,
    ``as_kcd_string``, ``as_sym_string``; and Arrow decoding of whole logs
    (:meth:`decode_arrow`, :meth:`decode_log`).

    After changing messages or signals, call :meth:`refresh` (as with cantools) so that
    lookups and codecs see the change.

    >>> db = load_string('''
    ... BO_ 256 Speed: 2 ECU
    ...  SG_ Kph : 0|16@1+ (0.01,0) [0|655.35] "km/h" Vector__XXX
    ... ''')
    >>> db.encode_message("Speed", {"Kph": 12.5})
    b'\\xe2\\x04'
    >>> db.get_message_by_frame_id(256).decode(b'\\xe2\\x04')
    {'Kph': 12.5}
    """

    def __init__(
        self,
        messages: list[Message] | None = None,
        nodes: list[Node] | None = None,
        buses: list[Bus] | None = None,
        version: str | None = None,
        dbc_specifics: DbcSpecifics | None = None,
        autosar_specifics: Any = None,
        frame_id_mask: int | None = None,
        strict: bool = True,
        sort_signals: Any = SORT_SIGNALS_DEFAULT,
    ) -> None:
        self._messages = messages or []
        self._nodes = nodes or []
        self._buses = buses or []
        self._version = version
        self._dbc = dbc_specifics
        self._autosar = autosar_specifics
        self._frame_id_mask = _ALL_MASK if frame_id_mask is None else frame_id_mask
        self._strict = strict
        self._sort_signals = sort_signals
        # What the model says beside messages and nodes (definitions, value tables, ...), and
        # messages cantools does not show (VECTOR__INDEPENDENT_SIG_MSG), kept for writing.
        self._rest: dict[str, Any] = {}
        self._hidden: list[dict[str, Any]] = []
        self._diagnostics: list[str] = []
        self.refresh()

    # -- what cantools shows -------------------------------------------------------------

    @property
    def messages(self) -> list[Message]:
        return self._messages

    @property
    def nodes(self) -> list[Node]:
        return self._nodes

    @property
    def buses(self) -> list[Bus]:
        return self._buses

    @property
    def version(self) -> str | None:
        return self._version

    @version.setter
    def version(self, value: str | None) -> None:
        self._version = value

    @property
    def dbc(self) -> DbcSpecifics | None:
        return self._dbc

    @dbc.setter
    def dbc(self, value: DbcSpecifics | None) -> None:
        self._dbc = value

    @property
    def autosar(self) -> Any:
        return self._autosar

    @property
    def diagnostics(self) -> list[str]:
        """The problems found while loading, ``FILE:LINE:COLUMN: what`` (bywire loads what
        a reasonable engineer accepts, and says what it accepted here)."""
        return list(self._diagnostics)

    @property
    def message_names(self) -> list[str]:
        """The messages' names, in the file's order."""
        return [m.name for m in self._messages]

    def get_message_by_name(self, name: str) -> Message:
        return self._by_name[name]

    def get_message_by_frame_id(self, frame_id: int, force_extended_id: bool = False) -> Message:
        """The message with this identifier: above 0x7FF (or with ``force_extended_id``) an
        extended one, as cantools looks them up."""
        if force_extended_id or frame_id > 0x7FF:
            frame_id |= _EXTENDED
        return self._by_frame_id[frame_id & (_EXTENDED | self._frame_id_mask)]

    def get_node_by_name(self, name: str) -> Node:
        for node in self._nodes:
            if node.name == name:
                return node
        raise KeyError(name)

    def get_bus_by_name(self, name: str) -> Bus:
        for bus in self._buses:
            if bus.name == name:
                return bus
        raise KeyError(name)

    def message_info(self, frame_id_or_name: int | str) -> dict[str, Any]:
        """A message's description as a dict (bywire's older call; ``Message`` has it all)."""
        return self._native.message_info(frame_id_or_name)

    # decode_message and encode_message are the native database's own methods, bound in
    # refresh(); these definitions document them and serve a masked frame identifier.

    def decode_message(
        self,
        frame_id_or_name: int | str,
        data: bytes,
        decode_choices: bool = True,
        scaling: bool = True,
        decode_containers: bool = False,
        allow_truncated: bool = False,
        force_extended_id: bool = False,
        allow_excess: bool = True,
    ) -> dict[str, Any]:
        """Decode ``data`` as cantools does: ``{signal: value}`` in cantools' order, choices
        as :class:`NamedSignalValue`; :class:`DecodeError` for data of the wrong size or an
        unknown multiplexer value, ``KeyError`` for an unknown message."""
        return self._message(frame_id_or_name, force_extended_id).decode(
            data, decode_choices, scaling, decode_containers, allow_truncated, allow_excess
        )

    def encode_message(
        self,
        frame_id_or_name: int | str,
        data: Mapping[str, Any],
        scaling: bool = True,
        padding: bool = False,
        strict: bool = True,
        force_extended_id: bool = False,
    ) -> bytes:
        """Encode signal values as cantools does (``strict``: every needed signal, no other,
        each within its range; choices by name or as either library's ``NamedSignalValue``)."""
        return self._message(frame_id_or_name, force_extended_id).encode(data, scaling, padding, strict)

    def _message(self, frame_id_or_name: int | str, force_extended_id: bool) -> Message:
        if isinstance(frame_id_or_name, str):
            return self.get_message_by_name(frame_id_or_name)
        if not isinstance(frame_id_or_name, int):
            raise ValueError(f"Invalid frame_id_or_name '{frame_id_or_name}'")
        if force_extended_id or frame_id_or_name > 0x7FF:
            frame_id_or_name |= _EXTENDED
        return self._by_frame_id[frame_id_or_name]

    def is_similar(self, other: Database, *, tolerance: float = 1e-12, include_format_specifics: bool = True) -> bool:
        """Whether two databases say the same, numbers equal within ``tolerance``."""
        return not self._differences(other, tolerance=tolerance, include_format_specifics=include_format_specifics)

    def _differences(
        self, other: Database, *, tolerance: float = 1e-12, include_format_specifics: bool = True
    ) -> list[dict[str, str]]:
        """Each difference between two databases: ``{path, self, other, reason}``."""
        found: list[dict[str, str]] = []
        _compare(self, other, "database", tolerance, include_format_specifics, set(), found)
        return found

    # -- reading and writing ---------------------------------------------------------------

    def _adders(database_format: str, encoding: str) -> tuple[Any, Any, Any]:  # type: ignore[misc]
        """cantools' add_FORMAT_string, add_FORMAT (an open file) and add_FORMAT_file: the
        format's messages appended, its nodes, version and definitions taken."""

        def add_string(self: Database, string: str) -> None:
            self._add(string.encode("utf-8"), database_format, "<string>")

        def add(self: Database, fp: IO[str]) -> None:
            add_string(self, fp.read())

        def add_file(self: Database, filename: str | os.PathLike[str], encoding: str = encoding) -> None:
            self._add(_read(filename, encoding), database_format, os.fspath(filename))

        return add_string, add, add_file

    add_dbc_string, add_dbc, add_dbc_file = _adders("dbc", "cp1252")
    add_kcd_string, add_kcd, add_kcd_file = _adders("kcd", "utf-8")
    add_sym_string, add_sym, add_sym_file = _adders("sym", "utf-8")
    add_arxml_string, add_arxml, add_arxml_file = _adders("arxml", "utf-8")
    del _adders

    def _add(self, data: bytes, database_format: str | None, origin: str) -> None:
        native = _native.Database.load_bytes(data, origin, False, database_format)
        self._take(native)
        self.refresh()

    def _take(self, native: Any) -> None:
        """Take a loaded model's messages and nodes (appended, as cantools adds), version
        and definitions."""
        model = json.loads(native.to_json())
        definitions = {d["name"]: AttributeDefinition(d) for d in model["attribute_defs"]}
        node_names = {n["name"]: _attribute(n["attributes"], "SystemNodeLongSymbol") or n["name"] for n in model["nodes"]}
        for message in model["messages"]:
            if message["name"] == "VECTOR__INDEPENDENT_SIG_MSG":
                self._hidden.append(message)
                continue
            self._messages.append(
                Message._of_model(
                    message,
                    definitions,
                    node_names,
                    self._sort_signals,
                    _cycle_time(message, definitions),
                    _enum_text(message, definitions, "GenMsgSendType"),
                    _frame_format(message, definitions),
                )
            )
        by_name = {m.name: m for m in self._messages}
        for container in model.get("containers", []):
            frame = by_name.get(container["message"])
            if frame is None:
                continue
            contained = []
            for pdu in container["pdus"]:
                message = Message._of_model(
                    pdu, definitions, node_names, self._sort_signals, _cycle_time(pdu, definitions), None, None
                )
                message.header_id = pdu["id"]
                contained.append(message)
            frame.contained_messages = contained
            frame.header_byte_order = "little_endian" if container["header_byte_order"] == "LittleEndian" else "big_endian"
            frame._container = container
        database_name = _attribute(model["attributes"], "DBName")
        for message in self._messages:
            message.bus_name = _attribute(message._model["attributes"], "BusName") or database_name or None
        self._nodes = []
        for node_model in model["nodes"]:
            node = Node(node_names[node_model["name"]], node_model["comment"])
            node.dbc = DbcSpecifics(
                {k: Attribute(next(iter(v.values())), definitions.get(k)) for k, v in node_model["attributes"]},
                definitions,
            )
            node._model = node_model
            self._nodes.append(node)
        self._version = model["version"]
        self._dbc = DbcSpecifics(
            {k: Attribute(next(iter(v.values())), definitions.get(k)) for k, v in model["attributes"]},
            definitions,
            {e["name"]: e for e in model["env_vars"]},
            {name: dict(values) for name, values in model["value_tables"]},
        )
        self._rest = {k: v for k, v in model.items() if k not in ("messages", "nodes", "version")}
        self._diagnostics += native.diagnostics

    def _to_model(self, sort_signals: Any = None) -> dict[str, Any]:
        model = dict(self._rest)
        model["version"] = self._version or ""
        model["nodes"] = [n._to_model() for n in self._nodes]
        messages = []
        for message in self._messages:
            written = message._to_model()
            if sort_signals is not None:
                order = [id(s) for s in sort_signals(list(message.signals))]
                by_id = dict(zip((id(s) for s in message.signals), written["signals"]))
                written["signals"] = [by_id[i] for i in order]
            messages.append(written)
        model["messages"] = messages + self._hidden
        return model

    def as_dbc_string(
        self,
        *,
        sort_signals: Any = SORT_SIGNALS_DEFAULT,
        sort_attribute_signals: Any = SORT_SIGNALS_DEFAULT,
        sort_attributes: Any = None,
        sort_choices: Any = None,
        shorten_long_names: bool = True,
    ) -> str:
        """The database as a DBC file (signals in reverse start-bit order unless
        ``sort_signals`` says otherwise, as cantools writes them). Long names a file gave
        (``System…LongSymbol``) are kept as it gave them; a name made longer than DBC's 32
        characters is written whole (cantools and bywire read it; Vector's tools may not).
        cantools' ordering hooks for attributes and choices, and ``shorten_long_names=False``,
        are not offered: asked for, they raise rather than be ignored."""
        unsupported = {
            "sort_attribute_signals": sort_attribute_signals != SORT_SIGNALS_DEFAULT,
            "sort_attributes": sort_attributes is not None,
            "sort_choices": sort_choices is not None,
            "shorten_long_names=False": not shorten_long_names,
        }
        asked = [name for name, given in unsupported.items() if given]
        if asked:
            raise NotImplementedError(f"as_dbc_string: {', '.join(asked)} is not offered by bywire's DBC writer")
        if sort_signals == SORT_SIGNALS_DEFAULT:
            sort_signals = sort_signals_by_start_bit_reversed if self._sort_signals else None
        return _native_of(self._to_model(sort_signals), []).write("dbc")[0]

    def as_kcd_string(self, *, sort_signals: Any = SORT_SIGNALS_DEFAULT) -> str:
        """The database as a KCD file (what KCD cannot say is left out)."""
        if sort_signals == SORT_SIGNALS_DEFAULT:
            sort_signals = None
        return _native_of(self._to_model(sort_signals), []).write("kcd")[0]

    def as_sym_string(self, *, sort_signals: Any = SORT_SIGNALS_DEFAULT) -> str:
        """The database as a PCAN Symbol file (what SYM cannot say is left out)."""
        if sort_signals == SORT_SIGNALS_DEFAULT:
            sort_signals = None
        return _native_of(self._to_model(sort_signals), []).write("sym")[0]

    def refresh(self) -> None:
        """Take the messages' current values into the lookups and the native codecs."""
        native = _native_of(self._to_model(), self._diagnostics)
        if self._strict:
            _refuse_layout(native)
        self._bind(native)

    def _bind(self, native: Any) -> None:
        """Decode and encode with ``native``, a database of these messages in this order."""
        self._native = native
        self._by_name = {m.name: m for m in self._messages}
        self._by_frame_id = {
            (m.frame_id & self._frame_id_mask) | (_EXTENDED if m.is_extended_frame else 0): m for m in self._messages
        }
        for index, message in enumerate(self._messages):
            message._codecs = self._native.message(index)
            # A container frame decodes into its PDUs, in Python (Message.decode).
            if not message.is_container:
                message.decode = message._codecs.decode
            message.encode = message._codecs.encode
        if self._frame_id_mask == _ALL_MASK and not any(m.is_container for m in self._messages):
            # The native calls take a name or an identifier themselves: no Python in between.
            self.decode_message = self._native.decode_message  # type: ignore[method-assign]
            self.encode_message = self._native.encode_message  # type: ignore[method-assign]
        else:
            self.__dict__.pop("decode_message", None)
            self.__dict__.pop("encode_message", None)

    def __getstate__(self) -> dict[str, Any]:
        state = {k: v for k, v in self.__dict__.items() if k not in ("_native", "decode_message", "encode_message", "_by_name", "_by_frame_id")}
        state["_messages"] = [
            {k: v for k, v in m.__dict__.items() if k not in ("_codecs", "decode", "encode")} for m in self._messages
        ]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        messages = []
        for fields in state["_messages"]:
            message = Message.__new__(Message)
            message.__dict__.update(fields)
            message._codecs = None
            messages.append(message)
        self.__dict__.update(state)
        self._messages = messages
        self.refresh()

    # -- Arrow ---------------------------------------------------------------------------

    def decode_arrow(self, frames: Any) -> Any:
        """Decode a batch or table of frames into one Arrow table per message (see
        :meth:`bywire.Database.decode_arrow`)."""
        from .. import _decode_all_batches

        return _decode_all_batches(self._native, frames)

    def decode_log(self, path: str | os.PathLike[str], batch_rows: int = 65_536) -> Any:
        """Decode every frame of a log of any format: one Arrow table per message."""
        from .. import _decode_log

        return _decode_log(self._native, path, batch_rows)

    def iter_decoded(self, frames: Any) -> Any:
        """Decode a stream of frame batches: ``(message, batch)`` pairs as they come."""
        from .. import _iter_decoded

        return _iter_decoded(self._native, frames)

    @classmethod
    def load(cls, path: str | os.PathLike[str], strict: bool = False, database_format: str | None = None) -> Database:
        """Load a database file as bywire's command line does: leniently, each problem in
        :attr:`diagnostics`, unless ``strict`` (the first problem raises :class:`ParseError`
        naming the file, line and column)."""
        native = _native.Database.load_bytes(_read(path, None), os.fspath(path), strict, _format_of(path, database_format))
        return _of_native(native)

    @classmethod
    def load_string(cls, text: str, strict: bool = False, database_format: str | None = None) -> Database:
        """Load database text as :meth:`load` loads a file."""
        return _of_native(_native.Database.load_bytes(text.encode("utf-8"), "<string>", strict, database_format))

    def __repr__(self) -> str:
        lines = [f"version('{self._version}')", ""]
        if self._nodes:
            lines += [repr(n) for n in self._nodes] + [""]
        for message in self._messages:
            lines.append(repr(message))
            lines += ["  " + repr(s) for s in message.signals]
            lines.append("")
        return "\n".join(lines)


def _compare(
    ours: Any, theirs: Any, path: str, tolerance: float, specifics: bool, seen: set[tuple[int, int]], found: list
) -> None:
    """Walk two objects side by side, recording where they differ (public fields only;
    ``dbc`` and ``autosar`` only with ``specifics``)."""
    if (id(ours), id(theirs)) in seen:
        return
    seen.add((id(ours), id(theirs)))

    def differ(reason: str) -> None:
        found.append({"path": path, "self": repr(ours), "other": repr(theirs), "reason": reason})

    numbers = (int, float)
    if isinstance(ours, numbers) and isinstance(theirs, numbers) and not isinstance(ours, bool) and not isinstance(theirs, bool):
        if not math.isclose(ours, theirs, rel_tol=tolerance, abs_tol=tolerance):
            differ("numbers differ")
    elif isinstance(ours, (str, bytes, bool)) or ours is None or theirs is None:
        if ours != theirs or type(ours) is not type(theirs) and not isinstance(ours, str):
            differ("values differ")
    elif isinstance(ours, Mapping) and isinstance(theirs, Mapping):
        if set(ours) != set(theirs):
            differ("keys differ")
            return
        for key in ours:
            _compare(ours[key], theirs[key], f"{path}[{key!r}]", tolerance, specifics, seen, found)
    elif isinstance(ours, (list, tuple)) and isinstance(theirs, (list, tuple)):
        if len(ours) != len(theirs):
            differ("lengths differ")
            return
        for index, (a, b) in enumerate(zip(ours, theirs)):
            _compare(a, b, f"{path}[{index}]", tolerance, specifics, seen, found)
    elif type(ours) is not type(theirs):
        differ("types differ")
    elif hasattr(ours, "__dict__"):
        for name in sorted(set(_fields(ours)) | set(_fields(theirs))):
            if not specifics and name in ("dbc", "autosar"):
                continue
            _compare(getattr(ours, name, None), getattr(theirs, name, None), f"{path}.{name}", tolerance, specifics, seen, found)
    elif ours != theirs:
        differ("values differ")


def _fields(thing: Any) -> list[str]:
    """An object's public fields: its attributes and properties, without callables."""
    names = {n.lstrip("_") for n in vars(thing) if not n.startswith("__")}
    names |= {n for n, v in vars(type(thing)).items() if isinstance(v, property)}
    return [n for n in names if not n.startswith("_") and hasattr(thing, n) and not callable(getattr(thing, n))]


def _of_native(native: Any, frame_id_mask: int | None = None, sort_signals: Any = SORT_SIGNALS_DEFAULT) -> Database:
    db = Database(frame_id_mask=frame_id_mask, strict=False, sort_signals=sort_signals)
    db._take(native)
    # Just loaded, the native database is these messages already, unless messages were kept
    # aside (its indices differ) or signals were sorted (its decode order follows theirs).
    as_loaded = not db._hidden and all(
        [id(s._model) for s in m.signals] == [id(s) for s in m._model["signals"]] for m in db._messages
    )
    if as_loaded:
        db._bind(native)
    else:
        db.refresh()
    return db


def _cycle_time(message: dict[str, Any], definitions: dict[str, AttributeDefinition]) -> int | None:
    definition = definitions.get("GenMsgCycleTime")
    if definition is None:
        return None
    value = _attribute(message["attributes"], "GenMsgCycleTime")
    if value:
        return value
    return definition.default_value or None


def _enum_text(message: dict[str, Any], definitions: dict[str, AttributeDefinition], name: str) -> str | None:
    definition = definitions.get(name)
    if definition is None:
        return None
    value = _attribute(message["attributes"], name)
    if value is None:
        return definition.default_value
    if definition.choices and isinstance(value, int) and 0 <= value < len(definition.choices):
        return definition.choices[value]
    return str(value)


#: VFrameFormat's values when a file defines it as an INT.
_FRAME_FORMATS = ["StandardCAN", "ExtendedCAN", "reserved", "J1939PG"] + ["reserved"] * 10 + ["StandardCAN_FD", "ExtendedCAN_FD"]


def _frame_format(message: dict[str, Any], definitions: dict[str, AttributeDefinition]) -> str | None:
    definition = definitions.get("VFrameFormat")
    if definition is None:
        return None
    choices = definition.choices or _FRAME_FORMATS
    value = _attribute(message["attributes"], "VFrameFormat")
    if value is None:
        default = definition.default_value
        if isinstance(default, int) and 0 <= default < len(choices):
            return choices[default]
        return default
    if isinstance(value, int) and 0 <= value < len(choices):
        return choices[value]
    return str(value)


def _read(filename: str | os.PathLike[str], encoding: str | None) -> bytes:
    """The file's bytes (FileNotFoundError and the like as Python raises them), as UTF-8
    when an encoding is given, else as they are (the readers tell UTF-8 from cp1252)."""
    with open(filename, "rb") as file:
        data = file.read()
    if encoding is None:
        return data
    return data.decode(encoding).encode("utf-8")


def _format_of(filename: str | os.PathLike[str], database_format: str | None) -> str | None:
    _check_format(database_format)
    if database_format is not None:
        return database_format
    extension = os.path.splitext(os.fspath(filename))[1][1:].lower()
    return extension if extension in (*FORMATS, "arxml", "cdd") else None


def _check_format(database_format: str | None) -> None:
    if database_format not in (*FORMATS, "arxml", "cdd", None):
        raise ValueError(
            f"expected database format 'arxml', 'dbc', 'kcd', 'sym', 'cdd' or None, but got '{database_format}'"
        )


def _load(
    data: bytes,
    origin: str,
    database_format: str | None,
    frame_id_mask: int | None,
    prune_choices: bool,
    strict: bool,
    sort_signals: Any,
) -> Database:
    try:
        native = _native.Database.load_bytes(data, origin, False, database_format)
    except ParseError as error:
        sniffed = database_format or _sniffed(data)
        raise UnsupportedDatabaseFormatError(**{f"e_{sniffed}": error}) from error
    if not database_format and native.message_names == [] and native.diagnostics and not json.loads(native.to_json())["nodes"]:
        # Lenient reading found nothing it knows: not a database of any format read.
        raise UnsupportedDatabaseFormatError(e_dbc=ParseError(native.diagnostics[0]))
    if (database_format or _sniffed(data)) == "cdd":
        # A diagnostic description: its DIDs, their data in the file's order, as cantools
        # gives a CDD.
        from .diagnostics import Database as Diagnostics, Did

        dids = _of_native(native, frame_id_mask, None)
        return Diagnostics([Did(m) for m in dids.messages])  # type: ignore[return-value]
    db = _of_native(native, frame_id_mask, sort_signals)
    if prune_choices:
        for message in db.messages:
            for signal in message.signals:
                _prune_choices(signal)
        db.refresh()
    db._strict = strict
    if strict:
        _refuse_layout(db._native)
    return db


def _sniffed(data: bytes) -> str:
    head = data.lstrip()[:200]
    if head.startswith(b"<"):
        start = data[:4096]
        return "arxml" if b"<AUTOSAR" in start else "cdd" if b"<CANDELA" in start else "kcd"
    if b"FormatVersion" in data[:4096]:
        return "sym"
    return "dbc"


def load_file(
    filename: str | os.PathLike[str],
    database_format: str | None = None,
    encoding: str | None = None,
    frame_id_mask: int | None = None,
    prune_choices: bool = False,
    strict: bool = True,
    cache_dir: str | None = None,
    sort_signals: Any = SORT_SIGNALS_DEFAULT,
) -> Database:
    """Load a database file (DBC, KCD, SYM or ARXML, by ``database_format``, else the extension,
    else the content). A missing file raises ``FileNotFoundError``; a file no format reads
    :class:`UnsupportedDatabaseFormatError` naming the file, line and column. ``strict``
    refuses signals past their message's end or sharing bits (cantools' strictness);
    ``cache_dir`` is accepted and not needed (loading is fast)."""
    database_format = _format_of(filename, database_format)
    data = _read(filename, encoding)
    return _load(data, os.fspath(filename), database_format, frame_id_mask, prune_choices, strict, sort_signals)


def load_string(
    string: str,
    database_format: str | None = None,
    frame_id_mask: int | None = None,
    prune_choices: bool = False,
    strict: bool = True,
    sort_signals: Any = SORT_SIGNALS_DEFAULT,
) -> Database:
    """Load database text (the format by ``database_format``, else by its content)."""
    _check_format(database_format)
    return _load(string.encode("utf-8"), "<string>", database_format, frame_id_mask, prune_choices, strict, sort_signals)


def load(
    fp: IO[str],
    database_format: str | None = None,
    frame_id_mask: int | None = None,
    prune_choices: bool = False,
    strict: bool = True,
    sort_signals: Any = SORT_SIGNALS_DEFAULT,
) -> Database:
    """Load a database from an open text file."""
    return load_string(fp.read(), database_format, frame_id_mask, prune_choices, strict, sort_signals)


def dump_file(
    database: Database,
    filename: str | os.PathLike[str],
    database_format: str | None = None,
    encoding: str | None = None,
    sort_signals: Any = SORT_SIGNALS_DEFAULT,
) -> None:
    """Write ``database`` to ``filename`` as DBC, KCD or SYM (by ``database_format``, else
    the extension)."""
    database_format = _format_of(filename, database_format) or "dbc"
    if database_format == "dbc":
        text, default_encoding, newline = database.as_dbc_string(sort_signals=sort_signals), "cp1252", "\r\n"
    elif database_format == "kcd":
        text, default_encoding, newline = database.as_kcd_string(sort_signals=sort_signals), "utf-8", None
    elif database_format == "sym":
        text, default_encoding, newline = database.as_sym_string(sort_signals=sort_signals), "cp1252", "\r\n"
    else:
        raise Error(f"Unsupported output database format '{database_format}'.")
    with open(filename, "w", encoding=encoding or default_encoding, newline=newline) as out:
        out.write(text)


_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def _prune_choices(signal: Signal) -> None:
    """cantools' ``prune_choices``: strip the longest common prefix ending in ``_`` that
    leaves every choice a valid identifier; a lone choice keeps its last run of letters."""
    choices = signal.choices
    if not choices:
        return
    names = [str(name) for name in choices.values()]
    if len(names) == 1:
        match = re.match(r"^[0-9A-Za-z_]*?_([A-Za-z_]+)$", names[0])
        cut = len(names[0]) - len(match.group(1)) if match else 0
    else:
        common = os.path.commonprefix(names)
        segments = common[: common.rfind("_")].split("_") if "_" in common else []
        cut = 0
        for count in range(len(segments), 0, -1):
            prefix = "_".join(segments[:count]) + "_"
            if all(_IDENTIFIER.match(name[len(prefix):]) for name in names):
                cut = len(prefix)
                break
    if cut:
        signal.choices = {number: NamedSignalValue(number, str(name)[cut:]) for number, name in choices.items()}
