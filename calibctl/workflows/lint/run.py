"""``calibctl lint`` on files and stored versions: each file linted by what it is (a camera export or ROS /
OpenCV file: ``lint.lint_file``; a rig export or bundle: ``rig_files``), then the store's active versions."""

from __future__ import annotations

from pathlib import Path

from calibctl.config import Settings
from calibctl.errors import UsageError
from calibctl.signing import is_mismatch
from calibctl.workflows.lint import lut_files, rig_files
from calibctl.workflows.lint.lint import LintResult, lint_store
from calibctl.workflows.store_admin import keys


def lint(
    settings: Settings,
    paths: list[Path],
    serial: str | None,
    all_serials: bool,
    *,
    require_signature: bool = False,
    trusted_keys: Path | None = None,
    against_store: bool = False,
) -> list[LintResult]:
    """Lint files and/or stored versions; with ``require_signature`` anything not signed by a trusted key
    is a ``signature`` error (a camera's exports and a rig's carry their version's signature in their
    header; a bundle's manifest carries its own). A LUT folder or header is
    ``lut_files``' (``against_store``, i.e. --db given: its source must be the active version); with
    ``against_store`` a camera export's numbers must be those of the version its header names."""
    if not paths and not serial and not all_serials:
        raise UsageError("nothing to lint", "name files, or pass --serial SERIAL or --all")
    trusted = keys.trusted_of(settings, trusted_keys) if require_signature else None
    if trusted is not None and not trusted.keys:
        raise UsageError(
            "--require-signature needs trusted keys", "pass --trusted-keys DIR or set trusted_keys"
        )
    # not required, a file's signature is still checked: one that does not match its content is an error
    file_keys = trusted or keys.known_keys(settings, trusted_keys)
    results = []
    for path in paths:
        found = (
            lut_files.lint_lut(path, file_keys, settings if against_store else None)
            or rig_files.lint_rig_file(path, settings.lint, file_keys)
            or [
                rig_files.lint_camera_file(
                    path, settings.lint, file_keys, settings if against_store else None
                )
            ]
        )
        results += found if trusted is not None else [_mismatches_only(r) for r in found]
    if serial or all_serials:
        results += lint_store(settings, serial, all_serials, trusted)
    return results


def _mismatches_only(result: LintResult) -> LintResult:
    """``result`` with only the signature findings every reader reports, keys or not: a signature that does
    not match (an unsigned file or a stranger's key is a finding under --require-signature only)."""
    result.findings = [f for f in result.findings if f.rule != "signature" or is_mismatch(f.message)]
    return result
