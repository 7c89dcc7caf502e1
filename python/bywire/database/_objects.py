"""The objects of :mod:`bywire.database`: ``Database``, ``Message``, ``Signal``, ``Node``,
with cantools' names, arguments and meanings.

The native module holds the truth while nothing changes: a loaded file's model (bywire-dbc's,
as JSON) fills these objects, and its codecs decode and encode. Each object keeps its part of
that model, so what cantools does not show (attribute values and definitions, value tables,
environment variables) survives a write; ``refresh()`` (or writing) gives the native side the
objects' current values."""

from __future__ import annotations

import json
from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from .. import _native
from .._values import NamedSignalValue
from .errors import DecodeError, Error

NO_NODE = "Vector__XXX"

SortSignals = Callable[[list["Signal"]], list["Signal"]] | None


def start_bit(signal: Signal) -> int:
    """Where the signal starts counted in network order: cantools' sort key."""
    if signal.byte_order == "big_endian":
        return 8 * (signal.start // 8) + (7 - signal.start % 8)
    return signal.start


def sort_signals_by_start_bit(signals: list[Signal]) -> list[Signal]:
    """The default order of a message's signals (cantools' default too)."""
    return sorted(signals, key=start_bit)


def sort_signals_by_name(signals: list[Signal]) -> list[Signal]:
    return sorted(signals, key=lambda s: s.name)


#: What ``sort_signals`` is unless given: by start bit.
SORT_SIGNALS_DEFAULT = "default"


def _sorted(signals: list[Signal], sort_signals: Any) -> list[Signal]:
    if sort_signals == SORT_SIGNALS_DEFAULT:
        return sort_signals_by_start_bit(signals)
    if callable(sort_signals):
        return list(sort_signals(signals))
    return list(signals)


def _attribute(attributes: list, name: str) -> Any:
    """A model attribute's value: the number or the string, None when absent."""
    for key, value in attributes:
        if key == name:
            return next(iter(value.values()))
    return None


def _set_attribute(attributes: list, name: str, value: Any) -> None:
    """Set (``value`` a number or a string) or remove (None) a model attribute."""
    kept = [pair for pair in attributes if pair[0] != name]
    if value is not None:
        kept.append([name, {"Str": value} if isinstance(value, str) else {"Number": value}])
    attributes[:] = kept


class Conversion:
    """How raw values become physical ones: ``scale``, ``offset``, ``choices`` and whether
    the raw value is a float (cantools' ``conversion`` objects, one class for all)."""

    def __init__(
        self,
        scale: float = 1,
        offset: float = 0,
        choices: dict[int, NamedSignalValue | str] | None = None,
        is_float: bool = False,
    ) -> None:
        self.scale = scale
        self.offset = offset
        self.is_float = is_float
        self.choices = _named_choices(choices)

    @staticmethod
    def factory(
        scale: float = 1,
        offset: float = 0,
        choices: dict[int, NamedSignalValue | str] | None = None,
        is_float: bool = False,
    ) -> Conversion:
        return Conversion(scale, offset, choices, is_float)

    def raw_to_scaled(self, raw_value: int | float, decode_choices: bool = True) -> Any:
        if decode_choices and self.choices and raw_value in self.choices:
            return self.choices[raw_value]
        if self.scale == 1 and self.offset == 0:
            return raw_value
        return raw_value * self.scale + self.offset

    def scaled_to_raw(self, scaled_value: Any) -> int | float:
        if isinstance(scaled_value, str):
            return self.choice_to_number(scaled_value)
        return self.numeric_scaled_to_raw(scaled_value)

    def numeric_scaled_to_raw(self, scaled_value: float) -> int | float:
        raw = scaled_value if self.scale == 1 and self.offset == 0 else (scaled_value - self.offset) / self.scale
        return raw if self.is_float else round(raw)

    def choice_to_number(self, choice: str | NamedSignalValue) -> int:
        for number, name in (self.choices or {}).items():
            if str(name) == str(choice):
                return number
        raise KeyError(choice)

    def __repr__(self) -> str:
        return f"Conversion(scale={self.scale}, offset={self.offset}, choices={self.choices}, is_float={self.is_float})"


def _named_choices(choices: Mapping[int, Any] | None) -> dict[int, NamedSignalValue] | None:
    # An OrderedDict, as cantools gives them (printed, it shows as one).
    if not choices:
        return None
    return OrderedDict(
        (number, name if isinstance(name, NamedSignalValue) else NamedSignalValue(number, str(name)))
        for number, name in choices.items()
    )


class Attribute:
    """A DBC attribute's value (``BA_``) with its definition's name."""

    def __init__(self, value: Any, definition: AttributeDefinition | None) -> None:
        self.value = value
        self.definition = definition

    @property
    def name(self) -> str:
        return self.definition.name if self.definition else ""

    def __repr__(self) -> str:
        return f"attribute('{self.name}', {self.value})"


class AttributeDefinition:
    """A DBC attribute definition (``BA_DEF_``): kind, range or choices, default."""

    def __init__(self, model: dict[str, Any]) -> None:
        self.name: str = model["name"]
        kind = model["kind"]
        self.type_name, details = (kind, None) if isinstance(kind, str) else next(iter(kind.items()))
        self.type_name = {"Int": "INT", "Hex": "HEX", "Float": "FLOAT", "Str": "STRING", "Enum": "ENUM"}[self.type_name]
        self.choices: list[str] | None = details if self.type_name == "ENUM" else None
        self.minimum, self.maximum = details if self.type_name in ("INT", "HEX", "FLOAT") else (None, None)
        default = model.get("default")
        self.default_value = None if default is None else next(iter(default.values()))
        scope = model["scope"]
        self.kind = {"Network": None, "Node": "BU_", "Message": "BO_", "Signal": "SG_", "EnvVar": "EV_"}[scope]

    def __repr__(self) -> str:
        return f"attribute_definition('{self.name}', {self.default_value})"


class DbcSpecifics:
    """What a DBC file says of an object beside cantools' common fields: its
    ``attributes`` (``{name: Attribute}``) and, on the database, ``attribute_definitions``,
    ``value_tables`` and ``environment_variables``."""

    def __init__(
        self,
        attributes: dict[str, Attribute] | None = None,
        attribute_definitions: dict[str, AttributeDefinition] | None = None,
        environment_variables: dict[str, Any] | None = None,
        value_tables: dict[str, dict[int, str]] | None = None,
    ) -> None:
        self.attributes = attributes if attributes is not None else {}
        self.attribute_definitions = attribute_definitions if attribute_definitions is not None else {}
        self.environment_variables = environment_variables if environment_variables is not None else {}
        self.value_tables = value_tables if value_tables is not None else {}


def _specifics(attributes: list, definitions: dict[str, AttributeDefinition]) -> DbcSpecifics:
    return DbcSpecifics(
        {name: Attribute(next(iter(value.values())), definitions.get(name)) for name, value in attributes},
        definitions,
    )


class _Commented:
    """cantools' ``comments`` (by language) and ``comment`` (the one it shows: unnamed, then
    FOR-ALL, then EN; set, it replaces them all)."""

    comments: dict[str | None, str] | None

    @property
    def comment(self) -> str | None:
        for language in (None, "FOR-ALL", "EN"):
            if self.comments and self.comments.get(language) is not None:
                return self.comments[language]
        return None

    @comment.setter
    def comment(self, value: str | None) -> None:
        self.comments = None if value is None else {None: value}


class Signal(_Commented):
    """A signal with cantools' attributes: ``name``, ``start``, ``length``, ``byte_order``
    (``'little_endian'``/``'big_endian'``), ``is_signed``, ``is_float``, ``scale``, ``offset``,
    ``minimum``, ``maximum``, ``unit``, ``choices``, ``raw_initial``/``initial``,
    ``receivers``, ``is_multiplexer``, ``multiplexer_ids``, ``multiplexer_signal``,
    ``comment``, ``spn``, ``dbc``."""

    def __init__(
        self,
        name: str,
        start: int,
        length: int,
        byte_order: str = "little_endian",
        is_signed: bool = False,
        raw_initial: int | float | None = None,
        raw_invalid: int | float | None = None,
        conversion: Conversion | None = None,
        minimum: float | None = None,
        maximum: float | None = None,
        unit: str | None = None,
        dbc_specifics: DbcSpecifics | None = None,
        comment: str | dict | None = None,
        receivers: list[str] | None = None,
        is_multiplexer: bool = False,
        multiplexer_ids: list[int] | None = None,
        multiplexer_signal: str | None = None,
        spn: int | None = None,
    ) -> None:
        self.name = name
        self.conversion = conversion or Conversion()
        self.minimum = minimum
        self.maximum = maximum
        self.start = start
        self.length = length
        self.byte_order = byte_order
        self.is_signed = is_signed
        self.raw_initial = raw_initial
        self.raw_invalid = raw_invalid
        self.unit = unit
        self.dbc = dbc_specifics or DbcSpecifics()
        self.receivers = receivers or []
        self.is_multiplexer = is_multiplexer
        self.multiplexer_ids = multiplexer_ids
        self.multiplexer_signal = multiplexer_signal
        self.spn = spn
        self.comments = {None: comment} if isinstance(comment, str) else comment
        self._model: dict[str, Any] | None = None

    # cantools computes these from the raw values and the conversion.
    @property
    def initial(self) -> Any:
        return None if self.raw_initial is None else self.conversion.raw_to_scaled(self.raw_initial)

    @initial.setter
    def initial(self, value: Any) -> None:
        self.raw_initial = None if value is None else self.conversion.scaled_to_raw(value)

    @property
    def invalid(self) -> Any:
        return None if self.raw_invalid is None else self.conversion.raw_to_scaled(self.raw_invalid)

    @property
    def scale(self) -> float:
        return self.conversion.scale

    @scale.setter
    def scale(self, value: float) -> None:
        self.conversion = Conversion(value, self.offset, self.choices, self.is_float)

    @property
    def offset(self) -> float:
        return self.conversion.offset

    @offset.setter
    def offset(self, value: float) -> None:
        self.conversion = Conversion(self.scale, value, self.choices, self.is_float)

    @property
    def choices(self) -> dict[int, NamedSignalValue] | None:
        return self.conversion.choices

    @choices.setter
    def choices(self, choices: dict[int, Any] | None) -> None:
        self.conversion = Conversion(self.scale, self.offset, choices, self.is_float)

    @property
    def is_float(self) -> bool:
        return self.conversion.is_float

    @is_float.setter
    def is_float(self, value: bool) -> None:
        self.conversion = Conversion(self.scale, self.offset, self.choices, value)

    def raw_to_scaled(self, raw_value: int | float, decode_choices: bool = True) -> Any:
        return self.conversion.raw_to_scaled(raw_value, decode_choices)

    def scaled_to_raw(self, scaled_value: Any) -> int | float:
        return self.conversion.scaled_to_raw(scaled_value)

    def choice_to_number(self, choice: str | NamedSignalValue) -> int:
        try:
            return self.conversion.choice_to_number(choice)
        except KeyError as error:
            raise KeyError(f"Choice {choice} not found in Signal {self.name}.") from error

    def __repr__(self) -> str:
        choices = None
        if self.choices is not None:
            choices = "{" + ", ".join(f"{value}: '{text}'" for value, text in self.choices.items()) + "}"
        return (
            f"signal('{self.name}', {self.start}, {self.length}, '{self.byte_order}', "
            f"{self.is_signed}, {self.raw_initial}, {self.scale}, {self.offset}, "
            f"{self.minimum}, {self.maximum}, '{self.unit}', {self.is_multiplexer}, "
            f"{self.multiplexer_ids}, {choices}, {self.spn}, {self.comments})"
        )

    @classmethod
    def _of_model(
        cls, model: dict[str, Any], mux_name: str | None, definitions: dict[str, AttributeDefinition]
    ) -> Signal:
        attributes = model["attributes"]
        value_type = model["value_type"]
        is_float = value_type in ("Float32", "Float64")
        signed = isinstance(value_type, dict) and value_type["Integer"]["signed"]
        minimum, maximum = model["minimum"], model["maximum"]
        if type(minimum) is int and type(maximum) is int and minimum == maximum == 0:
            minimum = maximum = None
        multiplexing = model["multiplexing"]
        kind, number = (multiplexing, None) if isinstance(multiplexing, str) else next(iter(multiplexing.items()))
        condition = model["mux_condition"]
        ids, switch = None, None
        if condition is not None:
            switch = condition["switch"]
            ids = sorted({v for low, high in condition["ranges"] for v in range(low, min(high, low + 65535) + 1)})
        elif number is not None:
            ids, switch = [number], mux_name
        receivers = [r for r in model["receivers"] if r != NO_NODE]
        signal = cls(
            name=_attribute(attributes, "SystemSignalLongSymbol") or model["name"],
            start=model["start_bit"],
            length=model["length"],
            byte_order="big_endian" if model["byte_order"] == "BigEndian" else "little_endian",
            is_signed=bool(signed),
            raw_initial=_number(_attribute(attributes, "GenSigStartValue")),
            conversion=Conversion(
                model["factor"],
                model["offset"],
                {k: v for k, v in model["value_descriptions"]},
                is_float,
            ),
            minimum=minimum,
            maximum=maximum,
            unit=model["unit"] or None,
            dbc_specifics=_specifics(attributes, definitions),
            comment=model["comment"],
            receivers=receivers,
            is_multiplexer=kind in ("Multiplexor", "MultiplexedMultiplexor"),
            multiplexer_ids=ids,
            multiplexer_signal=switch,
            spn=_number(_attribute(attributes, "SPN")),
        )
        signal._model = model
        return signal

    def _to_model(self, simple_mux: str | None) -> dict[str, Any]:
        model = json.loads(json.dumps(self._model)) if self._model else _new_signal_model()
        attributes = model["attributes"]
        long_name = _attribute(attributes, "SystemSignalLongSymbol")
        if self.name != (long_name or model["name"]):
            model["name"] = self.name
            _set_attribute(attributes, "SystemSignalLongSymbol", None)
        model["start_bit"] = self.start
        model["length"] = self.length
        model["byte_order"] = "BigEndian" if self.byte_order == "big_endian" else "LittleEndian"
        if self.is_float:
            model["value_type"] = "Float64" if self.length == 64 else "Float32"
        else:
            model["value_type"] = {"Integer": {"signed": bool(self.is_signed)}}
        model["factor"] = self.scale
        model["offset"] = self.offset
        model["minimum"] = 0 if self.minimum is None else self.minimum
        model["maximum"] = 0 if self.maximum is None else self.maximum
        model["unit"] = self.unit or ""
        model["receivers"] = list(self.receivers) or [NO_NODE]
        model["comment"] = self.comment
        model["value_descriptions"] = [[k, str(v)] for k, v in (self.choices or {}).items()]
        ids = self.multiplexer_ids or []
        simple = len(ids) == 1 and self.multiplexer_signal in (None, simple_mux)
        if ids and simple:
            model["multiplexing"] = {"MultiplexedMultiplexor" if self.is_multiplexer else "Multiplexed": ids[0]}
            model["mux_condition"] = None
        elif ids:
            model["multiplexing"] = "Multiplexor" if self.is_multiplexer else "None"
            model["mux_condition"] = {"switch": self.multiplexer_signal, "ranges": _ranges(ids)}
        else:
            model["multiplexing"] = "Multiplexor" if self.is_multiplexer else "None"
            model["mux_condition"] = None
        if _number(_attribute(attributes, "GenSigStartValue")) != self.raw_initial:
            _set_attribute(attributes, "GenSigStartValue", self.raw_initial)
        if _number(_attribute(attributes, "SPN")) != self.spn:
            _set_attribute(attributes, "SPN", self.spn)
        return model


def _number(value: Any) -> int | float | None:
    return value if isinstance(value, (int, float)) else None


def _ranges(ids: Iterable[int]) -> list[list[int]]:
    ranges: list[list[int]] = []
    for value in sorted(set(ids)):
        if ranges and ranges[-1][1] + 1 == value:
            ranges[-1][1] = value
        else:
            ranges.append([value, value])
    return ranges


def _new_signal_model() -> dict[str, Any]:
    return {
        "name": "",
        "start_bit": 0,
        "length": 1,
        "byte_order": "LittleEndian",
        "value_type": {"Integer": {"signed": False}},
        "factor": 1,
        "offset": 0,
        "minimum": 0,
        "maximum": 0,
        "unit": "",
        "receivers": [NO_NODE],
        "multiplexing": "None",
        "mux_condition": None,
        "comment": None,
        "attributes": [],
        "value_descriptions": [],
    }


class Message(_Commented):
    """A message with cantools' attributes (``frame_id``, ``name``, ``length``,
    ``is_extended_frame``, ``is_fd``, ``senders``, ``receivers``, ``send_type``,
    ``cycle_time``, ``signals``, ``comment``, ``protocol``, ``signal_tree``, ``dbc``) and its
    ``decode`` and ``encode``, which run natively once the message belongs to a loaded
    database (or after ``refresh()``)."""

    def __init__(
        self,
        frame_id: int,
        name: str,
        length: int,
        signals: list[Signal],
        contained_messages: list[Message] | None = None,
        header_id: int | None = None,
        header_byte_order: str = "big_endian",
        unused_bit_pattern: int = 0x00,
        comment: str | dict | None = None,
        senders: list[str] | None = None,
        send_type: str | None = None,
        cycle_time: int | None = None,
        dbc_specifics: DbcSpecifics | None = None,
        autosar_specifics: Any = None,
        is_extended_frame: bool = False,
        is_fd: bool = False,
        bus_name: str | None = None,
        signal_groups: list[Any] | None = None,
        strict: bool = True,
        protocol: str | None = None,
        sort_signals: Any = SORT_SIGNALS_DEFAULT,
    ) -> None:
        limit = 29 if is_extended_frame else 11
        if frame_id.bit_length() > limit:
            kind = "Extended" if is_extended_frame else "Standard"
            raise Error(f"{kind} frame id 0x{frame_id:x} is more than {limit} bits in message {name}.")
        self.frame_id = frame_id
        self.name = name
        self.length = length
        self.signals = _sorted(signals, sort_signals)
        self.contained_messages = contained_messages
        self.header_id = header_id
        self.header_byte_order = header_byte_order
        self.unused_bit_pattern = unused_bit_pattern
        self.comments = {None: comment} if isinstance(comment, str) else comment
        self.senders = senders or []
        self.send_type = send_type
        self.cycle_time = cycle_time
        self.dbc = dbc_specifics
        self.autosar = autosar_specifics
        self.is_extended_frame = is_extended_frame
        self.is_fd = is_fd
        self.bus_name = bus_name
        self.signal_groups = signal_groups
        self.protocol = protocol
        self._strict = strict
        self._model: dict[str, Any] | None = None
        self._loaded: dict[str, Any] = {}
        self._codecs: Any = None
        self.refresh(strict)

    @property
    def is_container(self) -> bool:
        return bool(self.contained_messages)

    @property
    def receivers(self) -> set[str]:
        return {r for s in self.signals for r in s.receivers}

    @property
    def signal_tree(self) -> list[Any]:
        """The signals as cantools nests them: names, and for each multiplexor
        ``{name: {value: [signals...]}}``."""
        return self._tree(None, None)

    def _tree(self, switch: str | None, value: int | None) -> list[Any]:
        nodes: list[Any] = []
        for signal in self.signals:
            if signal.multiplexer_signal != switch:
                continue
            if value is not None and value not in (signal.multiplexer_ids or ()):
                continue
            if not signal.is_multiplexer:
                nodes.append(signal.name)
                continue
            values: set[int] = set(signal.choices or {})
            for child in self.signals:
                if child.multiplexer_signal == signal.name:
                    values.update(child.multiplexer_ids or ())
            nodes.append({signal.name: {v: self._tree(signal.name, v) for v in sorted(values)}})
        return nodes

    def get_signal_by_name(self, name: str) -> Signal:
        for signal in self.signals:
            if signal.name == name:
                return signal
        raise KeyError(name)

    def is_multiplexed(self) -> bool:
        return any(s.is_multiplexer for s in self.signals)

    def decode(
        self,
        data: bytes,
        decode_choices: bool = True,
        scaling: bool = True,
        decode_containers: bool = False,
        allow_truncated: bool = False,
        allow_excess: bool = True,
    ) -> dict[str, Any]:
        """``{signal: value}`` as cantools decodes: choices as :class:`NamedSignalValue`,
        ordered as cantools orders them; a container frame (with ``decode_containers``) as
        :meth:`decode_container` gives it."""
        if self.is_container:
            if not decode_containers:
                raise DecodeError(
                    f'Message "{self.name}" is a container message, but decoding such messages has not been enabled!'
                )
            return self.decode_container(data, decode_choices, scaling, allow_truncated, allow_excess)  # type: ignore[return-value]
        return self._codec().decode(data, decode_choices, scaling, decode_containers, allow_truncated, allow_excess)

    def get_contained_message_by_header_id(self, header_id: int) -> Message | None:
        found = [m for m in self.contained_messages or [] if m.header_id == header_id]
        if len(found) > 1:
            raise Error(f'Container message "{self.name}" contains multiple contained messages exhibiting id 0x{header_id:x}')
        return found[0] if found else None

    def get_contained_message_by_name(self, name: str) -> Message | None:
        found = [m for m in self.contained_messages or [] if m.name == name]
        if len(found) > 1:
            raise Error(f'Container message "{self.name}" contains multiple contained messages named "{name}"')
        return found[0] if found else None

    def unpack_container(self, data: bytes, allow_truncated: bool = False) -> list[tuple[Any, bytes]]:
        """The PDUs of a container frame: ``(message, bytes)``, or ``(header_id, bytes)`` for
        a header the database does not know. A header of ID 0, or too few bytes left for a
        header, ends the frame (AUTOSAR's padding)."""
        if not self.is_container:
            raise DecodeError(f'Cannot unpack non-container message "{self.name}"')
        if len(data) > self.length:
            raise DecodeError(
                f'Container message "{self.name}" specified as exhibiting at most {self.length} but received a {len(data)} bytes long frame'
            )
        container = getattr(self, "_container", None) or {}
        id_size, length_size = (4, 4) if container.get("header") == "Long" else (3, 1)
        order = "little" if self.header_byte_order == "little_endian" else "big"
        result: list[tuple[Any, bytes]] = []
        pos = 0
        while pos + id_size + length_size <= len(data):
            header_id = int.from_bytes(data[pos : pos + id_size], order)
            if header_id == 0:
                break
            length = int.from_bytes(data[pos + id_size : pos + id_size + length_size], order)
            start = pos + id_size + length_size
            if start + length > len(data):
                if not allow_truncated:
                    raise DecodeError(
                        f'Malformed container message "{self.name}": Contained message {len(result) + 1} would exceed total message size.'
                    )
                length = len(data) - start
            contained = self.get_contained_message_by_header_id(header_id)
            result.append((contained if contained is not None else header_id, bytes(data[start : start + length])))
            pos = start + length
        return result

    def decode_container(
        self,
        data: bytes,
        decode_choices: bool = True,
        scaling: bool = True,
        allow_truncated: bool = False,
        allow_excess: bool = True,
    ) -> list[tuple[Any, Any]]:
        """Each PDU of a container frame decoded: ``(message, {signal: value})``; its bytes
        where the PDU is unknown or does not decode."""
        if not self.is_container:
            raise DecodeError(f'Message "{self.name}" is not a container')
        result: list[tuple[Any, Any]] = []
        for contained, pdu in self.unpack_container(data, allow_truncated):
            if not isinstance(contained, Message):
                result.append((contained, pdu))
                continue
            try:
                result.append((contained, contained.decode(pdu, decode_choices, scaling, False, allow_truncated, allow_excess)))
            except (ValueError, DecodeError):
                result.append((contained, pdu))
        return result

    def encode(self, data: Mapping[str, Any], scaling: bool = True, padding: bool = False, strict: bool = True) -> bytes:
        """The payload of these signal values, as cantools encodes it."""
        return self._codec().encode(data, scaling, padding, strict)

    def _codec(self) -> Any:
        if self._codecs is None:
            self.refresh()
        return self._codecs

    def refresh(self, strict: bool | None = None) -> None:
        """Take the message's current values (its signals, length...) into its codec."""
        database = _native_of({"messages": [self._to_model()]}, [])
        if strict if strict is not None else self._strict:
            _refuse_layout(database)
        self._codecs = database.message(0)

    def __repr__(self) -> str:
        return f"message('{self.name}', 0x{self.frame_id:x}, {self.is_extended_frame}, {self.length}, {self.comments})"

    @classmethod
    def _of_model(
        cls,
        model: dict[str, Any],
        definitions: dict[str, AttributeDefinition],
        node_names: dict[str, str],
        sort_signals: Any,
        cycle_time: int | None,
        send_type: str | None,
        frame_format: str | None,
    ) -> Message:
        mux = next((s["name"] for s in model["signals"] if s["multiplexing"] == "Multiplexor"), None)
        signals = [Signal._of_model(s, mux, definitions) for s in model["signals"]]
        for signal in signals:
            signal.receivers = [node_names.get(r, r) for r in signal.receivers]
        senders = [model["transmitter"]] + [s for s in model["senders"] if s != model["transmitter"]]
        senders = [node_names.get(s, s) for s in senders if s != NO_NODE]
        message = cls.__new__(cls)
        message.frame_id = model["id"]
        message.name = _attribute(model["attributes"], "SystemMessageLongSymbol") or model["name"]
        message.length = model["size"]
        message.signals = _sorted(signals, sort_signals)
        message.contained_messages = None
        message.header_id = None
        message.header_byte_order = "big_endian"
        message.unused_bit_pattern = 0
        message.comments = None if model["comment"] is None else {None: model["comment"]}
        message.senders = senders
        message.send_type = send_type
        message.cycle_time = cycle_time
        message.dbc = _specifics(model["attributes"], definitions)
        message.autosar = None
        message.is_extended_frame = model["extended"]
        message.is_fd = bool(frame_format and frame_format.endswith("_FD"))
        message.bus_name = None
        message.signal_groups = None
        message.protocol = "j1939" if frame_format == "J1939PG" else None
        message._strict = False
        message._model = model
        message._loaded = {"cycle_time": cycle_time, "senders": list(senders)}
        message._codecs = None
        return message

    def _to_model(self) -> dict[str, Any]:
        model: dict[str, Any] = dict(self._model) if self._model else {
            "id": 0, "extended": False, "name": "", "size": 0, "transmitter": NO_NODE,
            "senders": [], "signals": [], "comment": None, "attributes": [],
        }
        model["attributes"] = json.loads(json.dumps(model["attributes"]))
        long_name = _attribute(model["attributes"], "SystemMessageLongSymbol")
        if self.name != (long_name or model["name"]):
            model["name"] = self.name
            _set_attribute(model["attributes"], "SystemMessageLongSymbol", None)
        model["id"] = self.frame_id
        model["extended"] = bool(self.is_extended_frame)
        model["size"] = self.length
        if self.senders != self._loaded.get("senders"):
            model["transmitter"] = self.senders[0] if self.senders else NO_NODE
            model["senders"] = list(self.senders) if len(self.senders) > 1 else []
        model["comment"] = self.comment
        if self.cycle_time != self._loaded.get("cycle_time"):
            _set_attribute(model["attributes"], "GenMsgCycleTime", self.cycle_time)
        mux = next((s.name for s in self.signals if s.is_multiplexer and not s.multiplexer_ids), None)
        model["signals"] = [s._to_model(mux) for s in self.signals]
        return model


class Node:
    """A node (ECU): ``name``, ``comment``, ``dbc``."""

    def __init__(self, name: str, comment: str | None = None, dbc_specifics: DbcSpecifics | None = None) -> None:
        self.name = name
        self.comment = comment
        self.dbc = dbc_specifics
        self._model: dict[str, Any] | None = None

    def __repr__(self) -> str:
        return "node('{}', {})".format(self.name, f"'{self.comment}'" if self.comment is not None else None)

    def _to_model(self) -> dict[str, Any]:
        model = dict(self._model) if self._model else {"name": self.name, "comment": None, "attributes": []}
        if self.name != (_attribute(model["attributes"], "SystemNodeLongSymbol") or model["name"]):
            model["name"] = self.name
        model["comment"] = self.comment
        return model


class Bus:
    """A bus: ``name``, ``comment``, ``baudrate``, ``fd_baudrate``."""

    def __init__(self, name: str, comment: str | None = None, baudrate: int | None = None, fd_baudrate: int | None = None, autosar_specifics: Any = None) -> None:
        self.name, self.comment, self.baudrate, self.fd_baudrate = name, comment, baudrate, fd_baudrate
        self.autosar = autosar_specifics

    def __repr__(self) -> str:
        return "bus('{}', {})".format(self.name, f"'{self.comment}'" if self.comment is not None else None)


def _native_of(model: dict[str, Any], diagnostics: list[str]) -> Any:
    full = {
        "version": "", "new_symbols": [], "bit_timing": "", "nodes": [], "value_tables": [],
        "messages": [], "env_vars": [], "comment": None, "attribute_defs": [], "attributes": [],
        "signal_groups": [], "unknown": [],
    }
    full.update(model)
    return _native.Database.from_json(json.dumps(full), diagnostics)


def _refuse_layout(database: Any) -> None:
    """cantools' strict loading: a signal past its message's end or sharing bits is an error."""
    for _code, sentence in database.layout_errors():
        raise Error(sentence[0].upper() + sentence[1:] + ".")
