"""Shared pieces of the on-disk contract: strict base model, canonical JSON, content hashing.

Every document calibctl writes is a pydantic model with ``schema_version``. Models are strict:
unknown fields are refused (a typo in a hand-edited file is an error, not silently dropped), and
NaN / infinity are refused everywhere, because a non-finite number in a calibration is never data.
"""

from __future__ import annotations

import hashlib
import json
from datetime import UTC, datetime
from typing import Annotated, Any, TypeVar

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError

from calibctl.errors import InputError

T = TypeVar("T", bound=BaseModel)


class Document(BaseModel):
    """Base of every model in the contract."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True, validate_default=True)


def _utc(value: datetime) -> datetime:
    if value.tzinfo is None:
        raise ValueError("timestamps must carry a timezone (calibctl writes UTC)")
    return value.astimezone(UTC)


UtcDatetime = Annotated[datetime, AfterValidator(_utc)]
SERIAL_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._:-]{0,127}$"
"""Serials never contain '@' (SERIAL@N would be ambiguous), spaces or control characters."""
Sha256Hex = Annotated[str, Field(pattern=r"^[0-9a-f]{64}$", description="lower-case hex sha256")]


def utc_now() -> datetime:
    """Now, in UTC, truncated to microseconds (what every database keeps)."""
    return datetime.now(UTC)


def canonical_json_bytes(data: dict[str, Any]) -> bytes:
    """The bytes a content hash is taken over: sorted keys, no whitespace, UTF-8, finite numbers only.

    Python's float repr is the shortest string that round-trips a float64, so a document survives
    JSON -> store -> JSON bit-for-bit and its hash is stable across machines.
    """
    return json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode(
        "utf-8"
    )


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def content_hash(model: BaseModel, exclude: set[str] | None = None) -> str:
    """sha256 of the canonical JSON of ``model`` without the fields in ``exclude``."""
    return sha256_hex(canonical_json_bytes(model.model_dump(mode="json", exclude=exclude or {"content_sha256"})))


def validation_message(exc: ValidationError, source: str) -> str:
    """One line naming the first offending field path, e.g. ``camera_matrix.1.2: Input should be finite``."""
    parts = []
    for err in exc.errors()[:3]:
        where = ".".join(str(p) for p in err["loc"]) or "(document)"
        parts.append(f"{where}: {err['msg']}")
    more = f" (+{exc.error_count() - 3} more)" if exc.error_count() > 3 else ""
    return f"{source} is not a valid document: " + "; ".join(parts) + more


def parse_document(model: type[T], data: Any, source: str) -> T:
    """Validate ``data`` as ``model``; a failure is an InputError naming the field path."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise InputError(validation_message(exc, source), "fix the named field or re-export the file") from exc
