"""Type stubs of the native module (crates/bywire-py)."""

from os import PathLike
from typing import Any

import pyarrow as pa

class Error(Exception): ...
class ParseError(Error): ...
class DecodeError(Error): ...
class EncodeError(Error): ...
class LogError(Error): ...
class ScenarioError(Error): ...

class Database:
    @staticmethod
    def load(path: str | PathLike[str], strict: bool = False, database_format: str | None = None) -> Database: ...
    @staticmethod
    def load_string(text: str, strict: bool = False, database_format: str | None = None) -> Database: ...
    @staticmethod
    def load_bytes(data: bytes, origin: str, strict: bool = False, database_format: str | None = None) -> Database: ...
    @staticmethod
    def from_json(text: str, diagnostics: list[str] = ...) -> Database: ...
    def to_json(self) -> str: ...
    def write(self, database_format: str) -> tuple[str, list[str]]: ...
    def layout_errors(self) -> list[tuple[str, str]]: ...
    def index_of(self, frame_id_or_name: int | str) -> int: ...
    def message(self, index: int) -> MessageCodecs: ...
    @property
    def diagnostics(self) -> list[str]: ...
    @property
    def message_names(self) -> list[str]: ...
    def message_info(self, frame_id_or_name: int | str) -> dict[str, Any]: ...
    def decode_message(
        self,
        frame_id_or_name: int | str,
        data: bytes | bytearray | memoryview,
        decode_choices: bool = True,
        scaling: bool = True,
        decode_containers: bool = False,
        allow_truncated: bool = False,
        force_extended_id: bool = False,
        allow_excess: bool = True,
    ) -> dict[str, Any]: ...
    def encode_message(
        self,
        frame_id_or_name: int | str,
        data: dict[str, Any],
        scaling: bool = True,
        padding: bool = False,
        strict: bool = True,
        force_extended_id: bool = False,
    ) -> bytes: ...
    def decode_arrow(
        self, batch: pa.RecordBatch
    ) -> tuple[list[tuple[str, pa.RecordBatch]], int, dict[str, tuple[int, str]]]: ...

class MessageCodecs:
    def decode(
        self,
        data: bytes | bytearray | memoryview,
        decode_choices: bool = True,
        scaling: bool = True,
        decode_containers: bool = False,
        allow_truncated: bool = False,
        allow_excess: bool = True,
    ) -> dict[str, Any]: ...
    def encode(self, data: dict[str, Any], scaling: bool = True, padding: bool = False, strict: bool = True) -> bytes: ...

class CanBus:
    def __init__(self, spec: str, receive_own: bool = False) -> None: ...
    def send(
        self,
        id: int,
        extended: bool,
        remote: bool,
        fd: bool,
        brs: bool,
        esi: bool,
        data: bytes,
        dlc: int | None = None,
    ) -> None: ...
    def recv(
        self, timeout: float | None = None
    ) -> tuple[float, int, bool, bool, bool, bool, bool, bool, int, bytes, bool] | None: ...
    def shutdown(self) -> None: ...
    @property
    def spec(self) -> str: ...

def run_cli(argv: list[str]) -> int: ...

class LogBatches:
    def __init__(
        self,
        path: str | PathLike[str],
        batch_rows: int = 65536,
        byte_range: tuple[int, int] | None = None,
    ) -> None: ...
    @staticmethod
    def schema() -> pa.Schema: ...
    @property
    def format(self) -> str: ...
    def __iter__(self) -> LogBatches: ...
    def __next__(self) -> pa.RecordBatch: ...

def run_sim(
    scenario: str,
    seed: int,
    out: str | PathLike[str],
    payload: float | None = None,
    secoc: bool = False,
    max_seconds: float = 300.0,
) -> tuple[str, list[str]]: ...

def signals_long(
    table: pa.RecordBatch,
    message: str,
    vehicle: str | None = None,
    date: str | None = None,
    labelled: bool = True,
) -> pa.RecordBatch: ...
def write_lake_files(
    database: Database,
    parts: list[tuple[str, tuple[int, int] | None, str | None, str | None]],
    staging: str,
    prefix: str,
    compression: str = "snappy",
    batch_rows: int = 65536,
    open_files: int = 256,
) -> list[tuple[str, int]]: ...
def partition_folder(column: str, value: str | None = None) -> str: ...
