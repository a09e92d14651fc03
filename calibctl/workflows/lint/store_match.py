"""``lint FILE --db``: a camera export's numbers against the stored version its header names.

A header without its ``file-sha256`` line cannot vouch for the numbers below it (anyone can delete the
line and edit a number), and an intact one only says the file is what some ``calibctl export`` wrote.
With a store at hand lint can say more: the version the header names is read back (verified, like every
read) and the file's image size, camera matrix and distortion must be that version's to the last printed
digit; a header whose artifact sha256 is not this store's version is another store's calibration."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from calibctl.artifacts.lint import Finding
from calibctl.config import Settings
from calibctl.errors import NotFoundError
from calibctl.workflows.exports import formats

if TYPE_CHECKING:
    from calibctl.artifacts.calibration import CalibrationArtifact
    from calibctl.workflows.lint.lint import CalibrationFacts

RULE = "store-match"
# exports print every float with repr (17 significant digits at most): a stored number read back is the
# same double; the tolerance only absorbs a writer that prints 15 digits (OpenCV's FileStorage)
RELATIVE_TOLERANCE = 1e-12


def store_findings(
    settings: Settings, loaded: formats.CalibrationFile, facts: CalibrationFacts
) -> list[Finding]:
    """Findings of a ROS / OpenCV camera export with a calibctl header against the store (none for any other
    file: a bare file names no version, a rig export is ``rig lint``'s)."""
    header = loaded.header
    if header is None or loaded.kind == "calibctl" or loaded.rig_header is not None:
        return []
    from calibctl.workflows.store_admin.records import open_store

    serial, _, version = header.ref.rpartition("@")
    fix = f"export {header.ref} again from this store; never edit an export by hand"
    with open_store(settings) as store:
        try:
            stored = store.get_artifact(serial, int(version))
        except (NotFoundError, ValueError):
            return [
                Finding(
                    rule=RULE,
                    severity="warning",
                    message=f"the header names {header.ref}, which the store {store.url} does not hold: "
                    "its numbers were not compared",
                    fix="lint it against the store it was exported from (--db URL)",
                )
            ]
    if stored.content_sha256 != header.artifact_sha256:
        return [
            Finding(
                rule=RULE,
                severity="error",
                message=f"the header names {header.ref} sha256 {header.artifact_sha256[:12]}, "
                f"but this store's "
                f"{header.ref} is {stored.content_sha256[:12]}: another store's calibration",
                fix=fix,
            )
        ]
    differs = _differences(facts, stored)
    if not differs:
        return []
    return [
        Finding(
            rule=RULE,
            severity="error",
            message=f"the numbers are not {header.ref}'s: {'; '.join(differs)}",
            fix=fix,
        )
    ]


def _differences(facts: CalibrationFacts, stored: CalibrationArtifact) -> list[str]:
    """What the file says that the stored version does not, each as 'name file X, stored Y'."""
    out = []
    if facts.image_size is not None and tuple(facts.image_size) != tuple(stored.image_size):
        out.append(
            f"image size file {facts.image_size[0]}x{facts.image_size[1]}, stored "
            f"{stored.image_size[0]}x{stored.image_size[1]}"
        )
    K_file, K_stored = facts.camera_matrix, np.asarray(stored.camera_matrix, np.float64)
    for (i, j), name in {(0, 0): "fx", (1, 1): "fy", (0, 2): "cx", (1, 2): "cy", (0, 1): "skew"}.items():
        if not _same(K_file[i, j], K_stored[i, j]):
            out.append(f"{name} file {K_file[i, j]:.6g}, stored {K_stored[i, j]:.6g}")
    d_file, d_stored = np.asarray(facts.dist_coeffs, np.float64), np.asarray(stored.dist_coeffs, np.float64)
    n = max(d_file.size, d_stored.size)  # a ROS plumb_bob pads k1k2 with zeros to five
    d_file, d_stored = np.pad(d_file, (0, n - d_file.size)), np.pad(d_stored, (0, n - d_stored.size))
    bad = [k for k in range(n) if not _same(d_file[k], d_stored[k])]
    if bad:
        k = bad[0]
        out.append(f"distortion[{k}] file {d_file[k]:.6g}, stored {d_stored[k]:.6g}")
    return out


def _same(a: float, b: float) -> bool:
    return bool(abs(a - b) <= RELATIVE_TOLERANCE * max(abs(a), abs(b), 1.0))
