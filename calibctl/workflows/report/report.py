"""calibctl report: one stored calibration -> one self-contained HTML page a person reads.

Everything is drawn from the store: the artifact (parameters, covariance, held-out numbers, gates,
lint, provenance) and the capture session's corners, which are kept forever, so a version whose
images were pruned still gets its full report. Residuals are recomputed from the stored corners and
the stored per-view poses under the stored model; corners the solve removed are left out.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.session import CaptureSession
from calibctl.config import Settings
from calibctl.core.intrinsics import report_maps
from calibctl.core.intrinsics.solve import is_fisheye
from calibctl.errors import AlreadyExistsError, FileSystemError, InputError, NotFoundError
from calibctl.files import existing_target, file_errors, write_atomic
from calibctl.workflows.board.boards import board_spec
from calibctl.workflows.report.report_data import ReportData, ViewCorners
from calibctl.workflows.report.report_html import render_html
from calibctl.workflows.store_admin.records import open_store, parse_artifact_ref

MAX_REPORT_BYTES = 1_000_000


def _views(art: CalibrationArtifact, session: CaptureSession) -> list[ViewCorners]:
    K = np.asarray(art.camera_matrix, dtype=np.float64)
    D = np.asarray(art.dist_coeffs, dtype=np.float64)
    model_points = board_spec(art.board).object_points()
    removed = {(c.view, c.corner_id) for c in art.rejected_corners}
    by_name = {v.name: v for v in session.views}
    out = []
    for result in art.views:
        view = by_name.get(result.name)
        if view is None:
            continue
        keep = [i for i, cid in enumerate(view.corner_ids) if (view.name, cid) not in removed]
        ids = np.asarray(view.corner_ids, dtype=np.int64)[keep]
        corners = np.asarray(view.corners_px, dtype=np.float64)[keep]
        res = report_maps.reprojection_residuals(
            model_points[ids], corners, result.rvec, result.tvec_m, K, D, is_fisheye(art.model.name)
        )
        out.append(ViewCorners(result.name, corners, res, result.outlier, result.dropped))
    return out


def _uncertainty(art: CalibrationArtifact) -> report_maps.UncertaintyMap | None:
    cov = art.stdev.covariance
    if cov is None:
        return None
    try:
        return report_maps.projection_uncertainty(
            np.asarray(art.camera_matrix, dtype=np.float64),
            np.asarray(art.dist_coeffs, dtype=np.float64),
            np.asarray(cov.matrix, dtype=np.float64),
            cov.parameters,
            cov.aspect_ratio,
            art.image_size,
            fisheye=is_fisheye(art.model.name),
        )
    except (ValueError, IndexError) as exc:  # a foreign artifact whose covariance names another model
        raise InputError(
            f"{art.ref}: its stored covariance over {cov.parameters} does not fit its "
            f"{len(art.dist_coeffs)}-coefficient model ({exc})",
            "re-solve the camera, or re-import the artifact from the store that made it",
        ) from exc


def gather(settings: Settings, ref: str) -> ReportData:
    """Read the version ``ref`` (SERIAL or SERIAL@N; default the active one) and compute what is drawn."""
    serial, version = parse_artifact_ref(ref)
    with open_store(settings) as store:
        art = store.get_artifact(serial, version)
        active = store.active_version(art.serial) == art.version
        session, note = None, None
        if art.provenance.session_id is None:
            note = "no capture session is recorded for this version (imported), so no corners to draw"
        else:
            try:
                session = store.get_session(art.provenance.session_id)
            except NotFoundError:
                note = (
                    f"capture session {art.provenance.session_id} is not in this store, so no corners to draw"
                )
    views = _views(art, session) if session is not None else []
    K = np.asarray(art.camera_matrix, dtype=np.float64)
    D = np.asarray(art.dist_coeffs, dtype=np.float64)
    return ReportData(
        art,
        active,
        views,
        note,
        _uncertainty(art),
        report_maps.distortion_curve(K, D, art.image_size, fisheye=is_fisheye(art.model.name)),
    )


def page_path(serial: str, version: int, folder: Path | None = None) -> Path:
    """Where SERIAL@N's page goes by default: FOLDER (default: here)/SERIAL-vN-report.html."""
    return (folder or Path.cwd()) / f"{serial}-v{version}-report.html"


def default_path(art: CalibrationArtifact, folder: Path | None = None) -> Path:
    return page_path(art.serial, art.version, folder)


def write_report(
    settings: Settings,
    ref: str,
    out: Path | None,
    *,
    force: bool,
    extend: Callable[[ReportData], ReportData] | None = None,
) -> tuple[Path, ReportData]:
    """Render ``ref`` and write it atomically to ``out`` (default SERIAL-vN-report.html here). ``extend`` adds
    what rooms above this one know (``calibctl report``: the diff against the previous version, the
    trends)."""
    data = gather(settings, ref)
    if extend is not None:
        data = extend(data)
    html = render_html(data)
    path = out if out is not None else default_path(data.artifact)
    write_atomic(path, html, force=force)
    return path, data


def ready_folder(folder: Path) -> Path:
    """Create ``folder`` when missing; checked before a solve, so a solve is never stored without its
    report."""
    if folder.exists() and not folder.is_dir():
        raise FileSystemError(
            f"cannot write reports to {folder}: it is not a folder", "name a folder for --report"
        )
    with file_errors("create the report folder", folder):
        folder.mkdir(parents=True, exist_ok=True)
    with file_errors("write reports to", folder):  # a read-only folder too: a file is the only honest probe
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".calibctl-report-probe.")
        os.close(fd)
        os.unlink(probe)
    return folder


def ready_page(folder: Path, serial: str, version: int) -> Path:
    """The page ``solve --report`` will write for the version it is about to store, in a folder that
    ``ready_folder`` checked; one that exists already is refused up front (it is never overwritten),
    so a solve is not stored and then left without its report."""
    path = page_path(serial, version, folder)
    if existing_target(path) is not None:  # a symlink, FIFO or device there is refused too, before any store
        raise AlreadyExistsError(
            f"{path} already exists; nothing was stored",
            "move it away, or give --report another folder (a solve never overwrites a report)",
        )
    return path
