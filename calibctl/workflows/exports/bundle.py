"""A robot bundle: every file a robot loads from one stored rig version, in one folder, with a manifest.

``write_bundle`` writes the files and ``manifest.json`` (each file's sha256 and byte count, plus what the
caller describes: rig version, members, frames) into a temporary folder beside the target and renames it
into place, so a reader sees the old bundle or the new one, never half of one. An existing target is
refused unless ``force``, and ``force`` replaces only a folder whose manifest calibctl wrote and that holds
nothing but the files it lists (never a folder of someone else's files, nor a symlink: refused, naming
what to move). ``check_bundle`` is the manifest's lint: every listed file present, no symlink, and
unchanged.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Any

from calibctl import bounded
from calibctl.artifacts.common import jcs_bytes
from calibctl.artifacts.lint import Finding
from calibctl.errors import AlreadyExistsError, FileSystemError, UsageError
from calibctl.files import file_errors, new_file_mode

if TYPE_CHECKING:
    from calibctl.signing import Signer

MANIFEST = "manifest.json"
BUNDLE_FORMAT = "calibctl-robot-bundle"
BUNDLE_SCHEMA_VERSION = 1


def sha256_of(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def is_manifest(data: Any) -> bool:
    return isinstance(data, dict) and data.get("format") == BUNDLE_FORMAT


def _is_bundle_folder(path: Path) -> bool:
    try:
        return is_manifest(json.loads((path / MANIFEST).read_text(encoding="utf-8")))
    except (OSError, ValueError):
        return False


def check_target(
    out: Path, force: bool, what: str = "bundle", marker: str = MANIFEST, owned: Any = _is_bundle_folder
) -> None:
    """``out`` may be written: new, or (``force``) a ``what`` folder whose ``marker`` file calibctl wrote."""
    if out.exists() or out.is_symlink():
        if not force:
            raise AlreadyExistsError(
                f"{out} already exists",
                f"choose a new folder, or pass --force to replace a {what} calibctl wrote there",
            )
        if out.is_symlink() or not out.is_dir() or not owned(out):
            raise UsageError(
                f"{out} is not a {what} calibctl wrote (no calibctl {marker} in it): --force replaces "
                f"only a {what} folder",
                "choose a new folder",
            )
    if not out.parent.is_dir():
        raise FileSystemError(f"cannot write {out}: folder {out.parent} does not exist", "create it first")


MANIFEST_SIGNATURE = "manifest_signature"


def manifest_message(doc: Mapping[str, Any]) -> bytes:
    """What a manifest's own signature is over: the RFC 8785 form of every field but the signature (the
    files' sha256 and roles, the frames, the pair: the export's choices no rig signature covers)."""
    body = {k: v for k, v in doc.items() if k != MANIFEST_SIGNATURE}
    return f"calibctl-bundle-v1\n{sha256_of(jcs_bytes(body))}".encode("ascii")


def write_bundle(
    out: Path,
    files: Mapping[str, str],
    manifest: Mapping[str, Any],
    *,
    force: bool = False,
    signer: Signer | None = None,
) -> list[Path]:
    """Write ``files`` (relative name -> text) and the manifest (``manifest`` plus ``format``, its schema
    version and ``files``: name, sha256, bytes; with ``signer`` its own ``manifest_signature``) as the
    folder ``out``; returns the paths written."""
    out = Path(out)
    check_target(out, force)
    payloads = {name: text.encode("utf-8") for name, text in files.items()}
    _refuse_foreign_entries(out)
    doc = {
        "format": BUNDLE_FORMAT,
        "schema_version": BUNDLE_SCHEMA_VERSION,
        **manifest,
        "files": [
            {"path": name, "sha256": sha256_of(data), "bytes": len(data)} for name, data in payloads.items()
        ],
    }
    if signer is not None:
        doc[MANIFEST_SIGNATURE] = {
            "algorithm": "ed25519",
            "key_id": signer.key_id,
            "value": signer.sign(manifest_message(doc)),
            "public_key": signer.public_key_text,
        }
    payloads[MANIFEST] = (json.dumps(doc, indent=2, allow_nan=False) + "\n").encode("utf-8")
    return write_folder(out, payloads, "bundle")


def write_folder(out: Path, payloads: Mapping[str, bytes], what: str) -> list[Path]:
    """Write ``payloads`` (relative name -> bytes) as the folder ``out``, whole or not at all: into a
    temporary folder beside it, then renamed into place (an old ``out``, checked by the caller, replaced)."""
    file_mode = new_file_mode()
    with file_errors(f"write the {what}", out):
        tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name[:24]}.", suffix=".tmp"))
        try:
            for name, data in payloads.items():
                (tmp / name).write_bytes(data)
                os.chmod(tmp / name, file_mode)
            os.chmod(tmp, file_mode | ((file_mode & 0o444) >> 2))  # a folder's x bits follow its r bits
            if out.exists():
                old = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name[:24]}.", suffix=".old"))
                os.replace(out, old / out.name)
                os.replace(tmp, out)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(tmp, out)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    return [out / name for name in payloads]


def _foreign_entries(folder: Path, listed: object) -> list[tuple[str, str]]:
    """(name, how a message names it) of each entry of ``folder`` that is not a plain file its manifest lists
    (``listed``, the manifest's ``files``): a user's notes, a subfolder, a symlink (even one listed)."""
    paths = {e.get("path") for e in listed if isinstance(e, dict)} if isinstance(listed, list) else set()
    own = {MANIFEST} | paths
    out = []
    with file_errors("read the bundle folder", folder):
        for entry in sorted(os.scandir(folder), key=lambda e: e.name):
            if entry.is_symlink():
                out.append((entry.name, f"{entry.name} (a symlink)"))
            elif entry.name not in own or not entry.is_file(follow_symlinks=False):
                out.append((entry.name, entry.name + ("/" if entry.is_dir(follow_symlinks=False) else "")))
    return out


def _refuse_foreign_entries(out: Path) -> None:
    """``--force`` replaces only what the previous manifest lists: a folder that also holds anything else
    (a user's notes, a subfolder, a symlink, even one named like a bundle file) is refused, naming it."""
    if not out.is_dir() or out.is_symlink():
        return
    try:
        listed = json.loads((out / MANIFEST).read_text(encoding="utf-8")).get("files") or []
    except (OSError, ValueError, AttributeError):
        listed = []
    foreign = [label for _, label in _foreign_entries(out, listed)]
    if foreign:
        raise UsageError(
            f"{out} holds {', '.join(foreign)}, which its {MANIFEST} does not list: --force replaces only "
            "the files of the bundle calibctl wrote there; nothing was changed",
            f"move {', '.join(foreign)} out of {out}, or export into a new folder",
        )


def _finding(message: str, fix: str, severity: str = "error") -> Finding:
    return Finding(rule="bundle", severity=severity, message=message, fix=fix)


def check_bundle(manifest_path: Path, data: dict[str, Any]) -> list[Finding]:
    """Every problem of a bundle: a listed file missing, changed (sha256), a symlink or outside the folder
    (errors); anything else in the folder that the manifest does not list (a warning naming it)."""
    folder = manifest_path.parent
    ref = f"{data.get('rig')}@{data.get('version')}"
    fix = (
        f"export the bundle again (`calibctl rig export {ref} --format bundle -o DIR --force`); never "
        "edit it by hand"
    )
    listed = data.get("files")
    if not isinstance(listed, list) or not listed:
        return [_finding(f"{manifest_path}: the manifest lists no files", fix)]
    findings: list[Finding] = []
    for entry in listed:
        name, sha = (entry.get("path"), entry.get("sha256")) if isinstance(entry, dict) else (None, None)
        if not isinstance(name, str) or not isinstance(sha, str):
            findings.append(_finding(f"{manifest_path}: an entry of 'files' has no path and sha256", fix))
            continue
        rel = PurePosixPath(name)
        if rel.is_absolute() or ".." in rel.parts or not rel.parts:
            findings.append(_finding(f"{manifest_path}: {name} is outside the bundle folder", fix))
            continue
        path = folder / rel
        if path.is_symlink():
            findings.append(_finding(f"{path} is a symlink: a bundle holds its own files, never links", fix))
            continue
        if not path.is_file():
            findings.append(_finding(f"{path} is listed in the manifest but missing", fix))
            continue
        bounded.check_size(path)
        with file_errors("read", path):
            actual = sha256_of(path.read_bytes())
        if actual != sha:
            findings.append(
                _finding(
                    f"{path} was changed after calibctl wrote it (sha256 {actual[:12]}, the manifest "
                    f"records {sha[:12]})",
                    fix,
                )
            )
    names = {e.get("path") for e in listed if isinstance(e, dict)}
    unlisted = [label for name, label in _foreign_entries(folder, listed) if name not in names]
    if unlisted:  # calibctl did not write them, yet a robot loading the folder may read them
        findings.append(
            _finding(
                f"{folder} holds {', '.join(unlisted)}, which its {MANIFEST} does not list: not part of "
                f"{ref} as exported",
                f"move {', '.join(unlisted)} out of the bundle folder",
                severity="warning",
            )
        )
    return findings
