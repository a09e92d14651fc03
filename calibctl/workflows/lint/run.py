"""``calibctl lint`` on files and stored versions: each file linted by what it is (a camera export or ROS /
OpenCV file: ``lint.lint_file``; a rig export or bundle: ``rig_files``), then the store's active versions."""

from __future__ import annotations

from pathlib import Path

from calibctl.artifacts.lint import Finding
from calibctl.config import Settings
from calibctl.errors import UsageError
from calibctl.workflows.exports import formats
from calibctl.workflows.lint import rig_files
from calibctl.workflows.lint.lint import LintResult, lint_file, lint_store, signature_rule
from calibctl.workflows.store_admin import keys


def lint(
    settings: Settings,
    paths: list[Path],
    serial: str | None,
    all_serials: bool,
    *,
    require_signature: bool = False,
    trusted_keys: Path | None = None,
) -> list[LintResult]:
    """Lint files and/or stored versions; with ``require_signature`` anything not signed by a trusted key
    is a ``signature`` error (ROS and OpenCV exports carry no signature: lint the artifact export)."""
    if not paths and not serial and not all_serials:
        raise UsageError("nothing to lint", "name files, or pass --serial SERIAL or --all")
    trusted = keys.trusted_of(settings, trusted_keys) if require_signature else None
    if trusted is not None and not trusted.keys:
        raise UsageError("--require-signature needs trusted keys", "pass --trusted-keys DIR or set trusted_keys")
    results = []
    for path in paths:
        rig_results = rig_files.lint_rig_file(path, settings.lint)
        if rig_results is not None:
            if trusted is not None:  # a rig export carries no signature yet: --require-signature cannot pass it
                for result in rig_results:
                    result.findings.append(Finding(
                        rule="signature", severity="error",
                        message=f"{result.source} carries no signature (rig exports are not signed yet)",
                        fix="lint the stored rig and its members: `calibctl lint --rig RIG --require-signature`"))
            results += rig_results
            continue
        loaded = formats.load_calibration(path)
        result = lint_file(loaded, settings.lint)
        if trusted is not None:
            signature_rule(result, loaded.data if loaded.kind == "calibctl" else {}, trusted)
        results.append(result)
    if serial or all_serials:
        results += lint_store(settings, serial, all_serials, trusted)
    return results
