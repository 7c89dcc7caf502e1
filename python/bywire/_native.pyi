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
    def load(path: str | PathLike[str], strict: bool = False) -> Database: ...
    @staticmethod
    def load_string(text: str, strict: bool = False) -> Database: ...
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
        allow_excess: bool = True,
    ) -> dict[str, Any]: ...
    def encode_message(
        self,
        frame_id_or_name: int | str,
        data: dict[str, Any],
        scaling: bool = True,
        padding: bool = False,
        strict: bool = True,
    ) -> bytes: ...
    def decode_arrow(
        self, batch: pa.RecordBatch
    ) -> tuple[list[tuple[str, pa.RecordBatch]], int, dict[str, tuple[int, str]]]: ...

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
