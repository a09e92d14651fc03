"""The comment header that ties a ROS / OpenCV export to its artifact and proves the file is unchanged.

A camera_info or FileStorage file cannot carry the whole artifact, so calibctl writes three comment
lines at its top (after OpenCV's ``%YAML`` line, which must stay first)::

    # calibctl CAM-0042@3 accepted sha256 <content_sha256 of the artifact in the store>
    # calibctl evidence {"fit_outer_ring_rms_px":0.039,...,"sigma_fx_px":0.25,...}
    # calibctl file-sha256 <sha256 of every byte of the file except this line>

The first line names the version and its status (a rejected calibration says so in its export); the
evidence line carries what lint needs and the format has no field for (sigma(fx), the held-out outer
ring, how the square size was measured); the last one is checked by ``calibctl lint``, so an edited
number is a ``content-hash`` error. Anyone can check it: ``grep -v '^# calibctl file-sha256 ' FILE |
sha256sum``.

Exported where a signing key is configured, the file is also signed as it is: a ``# calibctl
file-signature ed25519 key_id K value V public_key P`` line after the hash line, the exporting store's
signature of the file's sha256 (``file_message``; the hash and this line are left out of it). The
artifact's own signature covers the version the header names, not the numbers in this file: anyone can
edit one and recompute ``file-sha256``; nobody without the key can re-sign. ``lint --require-signature``
asks for it (a file inside a bundle is covered by the manifest's signature instead).

A LUT header (``exports.lut``) also carries ``# calibctl signature ed25519 key_id K record_sha256 R value V``:
the store's signature of the artifact (over its content_sha256, as ``calibctl-record-v1``), the camera
counterpart of a rig export's ``rig-signature`` line.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, field
from typing import Any

from calibctl import bounded
from calibctl.artifacts.calibration import CalibrationArtifact, RecordSignature
from calibctl.errors import InputError
from calibctl.signing import Signer

_PREFIX = "# calibctl "
_REF = re.compile(
    r"^# calibctl (?P<ref>\S+@\d+)(?: (?P<status>accepted|rejected))? sha256 (?P<sha>[0-9a-f]{64})\s*$"
)
_EVIDENCE = re.compile(r"^# calibctl evidence (?P<json>\{.*\})\s*$")
_FILE_SHA = re.compile(r"^(?:# |<!-- )calibctl file-sha256 (?P<sha>[0-9a-f]{64})(?: -->)?\s*$")
_RIG_REF = re.compile(
    r"^(?:# |<!-- )calibctl rig (?P<ref>\S+@\d+) (?P<status>accepted|rejected) sha256 "
    r"(?P<sha>[0-9a-f]{64})(?: -->)?\s*$"
)
_RIG_NOT_STORED = re.compile(
    r"^(?:# |<!-- )calibctl rig not stored \(rig solve-folders\) (?P<status>accepted|rejected) "
    r"solution-sha256 (?P<sha>[0-9a-f]{64})(?: -->)?\s*$"
)
_SIGNATURE = re.compile(
    r"^(?:# |<!-- )calibctl (?:rig-)?signature (?P<algorithm>ed25519) key_id (?P<key_id>[0-9a-f]{64}) "
    r"record_sha256 (?P<record>[0-9a-f]{64}) value (?P<value>[A-Za-z0-9+/]{86}==)"
    r"(?: public_key (?P<public_key>[A-Za-z0-9+/]{43}=))?(?: -->)?\s*$"
)
_MEMBER = re.compile(
    r"^(?:# |<!-- )calibctl member (?P<ref>\S+@\d+) sha256 (?P<sha>[0-9a-f]{64})"
    r"(?: frame (?P<frame>\S+))?(?: -->)?\s*$"
)
_FILE_SIGNATURE = re.compile(
    r"^(?:# |<!-- )calibctl file-signature (?P<algorithm>ed25519) key_id (?P<key_id>[0-9a-f]{64}) "
    r"value (?P<value>[A-Za-z0-9+/]{86}==) public_key (?P<public_key>[A-Za-z0-9+/]{43}=)(?: -->)?\s*$"
)
HEADER_SCAN_LINES = 8


@dataclass(frozen=True)
class FileSignature:
    """A ``file-signature`` line: the exporting store's key over ``file_message(signed_file_sha256)``."""

    key_id: str
    value: str
    public_key: str
    signed_file_sha256: str  # the sha256 of the file as read (what the signature must cover)

    @property
    def message(self) -> bytes:
        return file_message(self.signed_file_sha256)


def file_message(file_sha256_hex: str) -> bytes:
    """The bytes a file signature is taken over."""
    return f"calibctl-file-v1\n{file_sha256_hex}".encode("ascii")


@dataclass(frozen=True)
class TraceHeader:
    ref: str
    status: str | None  # None: written before exports carried their status
    artifact_sha256: str
    evidence: dict[str, Any] = field(default_factory=dict)
    file_sha256: str | None = None  # None: written before exports were hashed
    actual_file_sha256: str | None = None
    signature: RecordSignature | None = None  # the artifact's store signature, when the export carries it
    file_signature: FileSignature | None = None  # the exporting store's signature of the file itself

    @property
    def intact(self) -> bool | None:
        """True/False when the file records its hash, None when it cannot be checked."""
        return None if self.file_sha256 is None else self.file_sha256 == self.actual_file_sha256


def evidence_of(art: CalibrationArtifact) -> dict[str, Any]:
    measurement = art.board.measurement
    return {
        "sigma_fx_px": art.stdev.sigma.get("fx"),
        "sigma_refused_reason": art.stdev.refused_reason,
        "fit_outer_ring_rms_px": art.held_out.fit_outer_ring_rms_px,
        "held_out_outer_ring_rms_px": art.held_out.outer_ring_rms_px,
        "square_size_status": measurement.status if measurement else None,
        "square_size_m": measurement.square_size_m if measurement else None,
    }


def _without_hash_line(text: str) -> str:
    return "".join(
        line
        for line in text.splitlines(keepends=True)
        if not (_FILE_SHA.match(line.rstrip("\r\n")) or _FILE_SIGNATURE.match(line.rstrip("\r\n")))
    )


def file_sha256(text: str) -> str:
    return hashlib.sha256(_without_hash_line(text).encode("utf-8")).hexdigest()


def _signature_line(word: str, signature: RecordSignature, open_: str = "# ", close: str = "") -> str:
    return (
        f"{open_}calibctl {word} {signature.algorithm} key_id {signature.key_id} record_sha256 "
        f"{signature.record_sha256} value {signature.value}"
        f"{f' public_key {signature.public_key}' if signature.public_key else ''}{close}\n"
    )


def sign_file(text: str, signer: Signer | None) -> str:
    """``text`` (an export with its ``file-sha256`` line) with a ``file-signature`` line after that line,
    by ``signer``; unchanged without a signer or a hash line (a JSON document carries its own hash)."""
    lines = text.splitlines(keepends=True)
    at = next((k for k, line in enumerate(lines[: HEADER_SCAN_LINES + 8]) if _FILE_SHA.match(line)), None)
    if signer is None or at is None:
        return text
    xml = lines[at].startswith("<!-- ")
    open_, close = ("<!-- ", " -->") if xml else ("# ", "")
    value = signer.sign(file_message(file_sha256(text)))
    line = (
        f"{open_}calibctl file-signature ed25519 key_id {signer.key_id} value {value} "
        f"public_key {signer.public_key_text}{close}\n"
    )
    return "".join(lines[: at + 1]) + line + "".join(lines[at + 1 :])


def _file_signature_in(head: list[str], actual_sha256: str) -> FileSignature | None:
    m = next((m for line in head if (m := _FILE_SIGNATURE.match(line))), None)
    if m is None:
        return None
    return FileSignature(m.group("key_id"), m.group("value"), m.group("public_key"), actual_sha256)


def _signature_in(head: list[str]) -> RecordSignature | None:
    return next(
        (
            RecordSignature(
                algorithm="ed25519",
                key_id=m.group("key_id"),
                record_sha256=m.group("record"),
                value=m.group("value"),
                public_key=m.group("public_key"),
            )
            for line in head
            if (m := _SIGNATURE.match(line))
        ),
        None,
    )


def stamp(art: CalibrationArtifact, body: str, *, signed: bool = False) -> str:
    """``body`` with the header inserted (after a leading ``%YAML`` directive, which must stay first);
    ``signed``: with a ``calibctl signature ...`` line, the artifact's store signature (when it has one)."""
    lines = [
        f"{_PREFIX}{art.ref} {art.status} sha256 {art.content_sha256}\n",
        f"{_PREFIX}evidence "
        f"{json.dumps(evidence_of(art), sort_keys=True, separators=(',', ':'), allow_nan=False)}\n",
    ]
    if signed and art.signature is not None:
        lines.append(_signature_line("signature", art.signature))
    directive, rest = ("", body)
    if body.startswith("%YAML"):
        first, _, rest = body.partition("\n")
        directive = first + "\n"
    text = directive + "".join(lines) + rest
    return directive + "".join(lines) + f"{_PREFIX}file-sha256 {file_sha256(text)}\n" + rest


@dataclass(frozen=True)
class RigTraceHeader:
    """The header of a rig export: the rig version (and, in a camera's file, the member) it was written
    from."""

    ref: str  # RIG@N, or NOT_STORED for `rig solve-folders --export-dir`
    status: str
    rig_sha256: str  # the rig version's content_sha256 (not stored: the solution's sha256)
    members: tuple[tuple[str, str, str | None], ...]  # (SERIAL@VERSION, content_sha256, ROS frame)
    file_sha256: str | None
    actual_file_sha256: str | None
    signature: RecordSignature | None = None  # the rig version's store signature (over rig_sha256)
    file_signature: FileSignature | None = None  # the exporting store's signature of the file itself

    @property
    def intact(self) -> bool | None:
        return None if self.file_sha256 is None else self.file_sha256 == self.actual_file_sha256


NOT_STORED = "not-stored"


def stamp_rig(
    ref: str,
    status: str,
    rig_sha256: str,
    body: str,
    members: tuple[tuple[str, str, str | None], ...] = (),
    signature: RecordSignature | None = None,
) -> str:
    """``body`` (YAML, OpenCV YAML or XML) with a rig header: ``calibctl rig RIG@N STATUS sha256 S`` (``ref``
    NOT_STORED: ``calibctl rig not stored (rig solve-folders) STATUS solution-sha256 S``), the rig version's
    ``calibctl rig-signature ...`` when it is signed, one ``calibctl member SERIAL@V sha256 S frame F`` line
    per camera the file describes, and the file hash. A leading ``%YAML`` directive or ``<?xml`` declaration
    stays first; XML gets the lines as comments."""
    xml = body.startswith("<")  # a URDF robot or its joints alone: XML comments
    open_, close = ("<!-- ", " -->") if xml else ("# ", "")
    lines = [
        f"{open_}calibctl rig not stored (rig solve-folders) {status} solution-sha256 {rig_sha256}{close}\n"
        if ref == NOT_STORED
        else f"{open_}calibctl rig {ref} {status} sha256 {rig_sha256}{close}\n"
    ]
    if signature is not None:
        lines.append(_signature_line("rig-signature", signature, open_, close))
    lines += [
        f"{open_}calibctl member {m} sha256 {sha}{f' frame {frame}' if frame else ''}{close}\n"
        for m, sha, frame in members
    ]
    directive, rest = "", body
    if body.startswith(("%YAML", "<?xml")):
        first, _, rest = body.partition("\n")
        directive = first + "\n"
    text = directive + "".join(lines) + rest
    return directive + "".join(lines) + f"{open_}calibctl file-sha256 {file_sha256(text)}{close}\n" + rest


def read_rig(text: str) -> RigTraceHeader | None:
    """The rig header of ``text``, or None (not a rig export, or one written before rig exports were
    hashed)."""
    head = text.splitlines()[: HEADER_SCAN_LINES + 8]
    ref = next((m for line in head if (m := _RIG_REF.match(line) or _RIG_NOT_STORED.match(line))), None)
    if ref is None:
        return None
    members = tuple(
        (m.group("ref"), m.group("sha"), m.group("frame")) for line in head if (m := _MEMBER.match(line))
    )
    sha = next((m.group("sha") for line in head if (m := _FILE_SHA.match(line))), None)
    seal = _signature_in(head)
    actual = file_sha256(text)  # hashed once: the hash line and the file signature check the same bytes
    return RigTraceHeader(
        ref.groupdict().get("ref") or NOT_STORED,
        ref.group("status"),
        ref.group("sha"),
        members,
        sha,
        actual if sha else None,
        seal,
        _file_signature_in(head, actual),
    )


def read(text: str) -> TraceHeader | None:
    """The header of ``text``, or None when it has none (a file not written by calibctl export)."""
    head = text.splitlines()[:HEADER_SCAN_LINES]
    ref = next((m for line in head if (m := _REF.match(line))), None)
    if ref is None:
        return None
    evidence_match = next((m for line in head if (m := _EVIDENCE.match(line))), None)
    try:
        evidence = (
            bounded.parse_json(evidence_match.group("json"), "the trace header") if evidence_match else {}
        )
    except InputError:  # an unreadable evidence line vouches for nothing; the file hash still decides
        evidence = {}
    sha = next((m.group("sha") for line in head if (m := _FILE_SHA.match(line))), None)
    actual = file_sha256(text)  # hashed once: the hash line and the file signature check the same bytes
    return TraceHeader(
        ref=ref.group("ref"),
        status=ref.group("status"),
        artifact_sha256=ref.group("sha"),
        evidence=evidence if isinstance(evidence, dict) else {},
        file_sha256=sha,
        actual_file_sha256=actual if sha else None,
        signature=_signature_in(head),
        file_signature=_file_signature_in(head, actual),
    )
