"""Shared pieces of the on-disk contract: strict base model, canonical JSON, content hashing.

Every document calibctl writes is a pydantic model with ``schema_version``. Models are strict:
unknown fields are refused (a typo in a hand-edited file is an error, not silently dropped), and
NaN / infinity are refused everywhere, because a non-finite number in a calibration is never data.
"""

from __future__ import annotations

import hashlib
import json
import math
from datetime import UTC, datetime
from typing import Annotated, Any, Literal, TypeVar

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError

from calibctl.errors import InputError, named_list

T = TypeVar("T", bound=BaseModel)


class Document(BaseModel):
    """Base of every model in the contract."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True, validate_default=True)


def _utc(value: datetime) -> datetime:
    if value.tzinfo is None:
        raise ValueError("timestamps must carry a timezone (calibctl writes UTC)")
    return value.astimezone(UTC)


UtcDatetime = Annotated[datetime, AfterValidator(_utc)]
MAX_VERSION = 2**31 - 1
"""The largest version/revision: what an INTEGER column holds on PostgreSQL (and SQLite). Refused above."""
SERIAL_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._:-]{0,127}$"
"""Serials never contain '@' (SERIAL@N would be ambiguous), spaces or control characters."""
Sha256Hex = Annotated[str, Field(pattern=r"^[0-9a-f]{64}$", description="lower-case hex sha256")]


def utc_now() -> datetime:
    """Now, in UTC, truncated to microseconds (what every database keeps)."""
    return datetime.now(UTC)


def canonical_json_bytes(data: dict[str, Any]) -> bytes:
    """Sorted keys, no whitespace, UTF-8, finite numbers only: how the store keeps documents, and the
    bytes the *legacy* artifact hash (``sha256-python-json``) was taken over.

    Python's float repr is the shortest string that round-trips a float64, so a document survives
    JSON -> store -> JSON bit-for-bit.
    """
    return json.dumps(
        data, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False
    ).encode("utf-8")


MAX_EXACT_INT = 2**53 - 1  # Number.MAX_SAFE_INTEGER


def _jcs_string(text: str) -> str:
    # Python's escaping with ensure_ascii=False is JCS's: only '"', '\\' and U+0000..U+001F, in the
    # short forms \b \t \n \f \r where they exist, else \u00xx in lower-case hex.
    return json.dumps(text, ensure_ascii=False)


def _jcs_number(value: float) -> str:
    """ECMAScript Number.prototype.toString (RFC 8785 section 3.2.2.3), from Python's shortest repr."""
    if not math.isfinite(value):
        raise ValueError(f"{value} has no JSON form")
    if value.is_integer() and abs(value) <= MAX_EXACT_INT:
        return str(int(value))  # 1.0 -> "1", -0.0 -> "0"
    plain = repr(value)
    if "e" not in plain:  # 1e-4 <= |x| < 1e16: Python's shortest digits in ECMAScript's own layout
        return plain.removesuffix(".0")
    sign, text = ("-", repr(-value)) if value < 0 else ("", repr(value))
    mantissa, _, exp_text = text.partition("e")
    whole, _, frac = mantissa.partition(".")
    joined = whole + frac
    digits = joined.lstrip("0")
    n = len(whole) + int(exp_text or 0) - (len(joined) - len(digits))  # value = 0.DIGITS x 10^n
    digits = digits.rstrip("0")
    k = len(digits)
    if k <= n <= 21:
        body = digits + "0" * (n - k)
    elif 0 < n <= 21:
        body = digits[:n] + "." + digits[n:]
    elif -6 < n <= 0:
        body = "0." + "0" * -n + digits
    else:
        e = n - 1
        body = digits[0] + ("." + digits[1:] if k > 1 else "") + "e" + ("+" if e > 0 else "-") + str(abs(e))
    return sign + body


def _jcs(value: Any) -> str:
    if value is None:
        return "null"
    if value is True:
        return "true"
    if value is False:
        return "false"
    if isinstance(value, int):
        if abs(value) > MAX_EXACT_INT:
            raise ValueError(f"{value} is not exactly representable as an IEEE-754 double")
        return _jcs_number(float(value))
    if isinstance(value, float):
        return _jcs_number(value)
    if isinstance(value, str):
        return _jcs_string(value)
    if isinstance(value, list | tuple):
        return "[" + ",".join(_jcs(v) for v in value) + "]"
    if isinstance(value, dict):
        keys = sorted(value, key=lambda k: k.encode("utf-16-be"))  # RFC 8785: by UTF-16 code units
        return "{" + ",".join(_jcs_string(k) + ":" + _jcs(value[k]) for k in keys) + "}"
    raise TypeError(f"{type(value).__name__} has no JSON form")


def jcs_bytes(data: Any) -> bytes:
    """RFC 8785 JSON Canonicalization Scheme: the bytes the artifact hash (``sha256-rfc8785``) is taken
    over, reproducible in any language with a JCS library (see docs/content-hash.md)."""
    return _jcs(data).encode("utf-8")


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


HashAlgorithm = Literal["sha256-rfc8785", "sha256-python-json"]
CURRENT_HASH: HashAlgorithm = "sha256-rfc8785"
LEGACY_HASH: HashAlgorithm = "sha256-python-json"


def content_hash(
    model: BaseModel, exclude: set[str] | None = None, algorithm: HashAlgorithm = LEGACY_HASH
) -> str:
    """sha256 of the canonical JSON of ``model`` without the fields in ``exclude``."""
    data = model.model_dump(mode="json", exclude=exclude or {"content_sha256"})
    return sha256_hex(jcs_bytes(data) if algorithm == CURRENT_HASH else canonical_json_bytes(data))


def validation_message(exc: ValidationError, source: str) -> str:
    """One line naming the first offending field path, e.g. ``camera_matrix.1.2: Input should be finite``."""
    parts = [f"{'.'.join(str(p) for p in err['loc']) or '(document)'}: {err['msg']}" for err in exc.errors()]
    return f"{source} is not a valid document: {named_list(parts, 3, sep='; ')}"


def parse_document(model: type[T], data: Any, source: str) -> T:
    """Validate ``data`` as ``model``; a failure is an InputError naming the field path."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise InputError(
            validation_message(exc, source), "fix the named field or re-export the file"
        ) from exc
