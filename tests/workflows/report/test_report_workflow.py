"""calibctl report: the page shows the artifact's numbers, is byte-identical when regenerated, stays
under 1 MB, and still draws everything from the stored corners once the images are pruned."""

from __future__ import annotations

import re

import numpy as np
import pytest

from calibctl.artifacts.calibration import UNSEALED
from calibctl.config import load_settings
from calibctl.errors import InputError
from calibctl.store.repository import Store
from calibctl.workflows.camera import solve as solve_workflow
from calibctl.workflows.report import report as report_workflow
from calibctl.workflows.report.report_html import num
from tests.artifacts.factories import measured_board
from tests.workflows.sessions import synthetic_capture


@pytest.fixture
def solved(tmp_path):
    settings = load_settings(
        db=f"sqlite:///{tmp_path / 'w.db'}", station="st-test", operator="tester", env={}
    )
    session = synthetic_capture(measured_board())
    with Store.open(settings.db_url) as store:
        board = store.add_board(session.board)
        session = session.model_copy(update={"board": board})
        store.add_session(session)
    art = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id)).artifact
    return settings, art


def shown(html: str) -> dict[str, str]:
    """Every number the page marks with data-key, as shown."""
    return dict(re.findall(r'data-key="([^"]+)">([^<]*)<', html))


def test_the_numbers_shown_are_the_artifacts(solved, tmp_path):
    settings, art = solved
    path, data = report_workflow.write_report(settings, art.serial, tmp_path / "r.html", force=False)
    values = shown(path.read_text(encoding="utf-8"))
    assert values["status"] == "accepted" and values["lint"] == "lint: clean"
    assert values["fx"] == num(art.fx) and values["cy"] == num(art.camera_matrix[1][2])
    for name in ("fx", "fy", "cx", "cy"):
        assert values[f"sigma_{name}"] == num(art.stdev.sigma[name])
    assert values["k1"] == num(art.dist_coeffs[0], 5) and values["sigma_k2"] == num(art.stdev.sigma["k2"], 5)
    assert values["rms_px"] == num(art.rms_px) and values["held_out_rms_px"] == num(art.held_out.rms_px)
    for i, view in enumerate(art.views):
        assert values[f"view_rms_{i}"] == num(view.rms_px)
    for i, ring in enumerate(art.held_out.by_radius):
        assert values[f"ring_held_{i}"] == num(ring.held_out_rms_px)
    for i, octant in enumerate(art.held_out.by_octant):
        assert values[f"octant_fit_{i}"] == num(octant.fit_rms_px)
    assert all(values[f"gate_{g.gate}"] == ("pass" if g.passed else "FAIL") for g in art.gates)
    # the residuals recomputed from the stored corners and poses are the solve's
    res = np.concatenate([v.residuals_px for v in data.views])
    assert np.sqrt(np.mean(np.sum(res**2, axis=1))) == pytest.approx(art.rms_px, rel=1e-6)
    # the projection uncertainty at the centre is at least the principal point's own sigma
    assert float(values["uncertainty_centre"]) >= min(art.stdev.sigma["cx"], art.stdev.sigma["cy"]) - 0.01
    assert float(values["uncertainty_max"]) >= float(values["uncertainty_centre"])


def test_regenerating_is_byte_identical_and_under_a_megabyte(solved, tmp_path):
    settings, art = solved
    a, _ = report_workflow.write_report(
        settings, f"{art.serial}@{art.version}", tmp_path / "a.html", force=False
    )
    b, _ = report_workflow.write_report(settings, art.serial, tmp_path / "b.html", force=False)
    assert a.read_bytes() == b.read_bytes()
    assert 10_000 < a.stat().st_size < report_workflow.MAX_REPORT_BYTES
    text = a.read_text(encoding="utf-8")
    assert "http://" not in text.replace("http://www.w3.org/2000/svg", "") and "https://" not in text
    assert "<script" not in text


def test_an_artifact_without_covariance_or_session_says_why(solved, tmp_path):
    settings, art = solved
    old = art.model_copy(
        update={
            "stdev": art.stdev.model_copy(update={"covariance": None}),
            "provenance": art.provenance.model_copy(update={"session_id": None}),
        }
    )
    data = report_workflow.ReportData(
        old,
        False,
        [],
        "no capture session is recorded for this version (imported)",
        None,
        report_workflow.gather(settings, art.serial).distortion,
    )
    html = report_workflow.render_html(data)
    assert "made before calibctl stored it" in html and "no capture session is recorded" in html


def test_a_200_view_session_stays_under_a_megabyte(solved):
    settings, art = solved
    data = report_workflow.gather(settings, art.serial)
    copies = -(-200 // len(art.views))
    big = report_workflow.ReportData(
        art.model_copy(update={"views": (art.views * copies)[:200]}),
        True,
        (data.views * copies)[:200],
        None,
        data.uncertainty,
        data.distortion,
    )
    corners = sum(len(v.corners_px) for v in big.views)
    html = report_workflow.render_html(big)
    assert corners > 10_000 and len(html.encode()) < report_workflow.MAX_REPORT_BYTES
    assert f"every corner used ({corners})" in html and "th corner drawn" in html


def test_a_covariance_that_does_not_fit_the_model_exits_2_naming_it(solved, tmp_path):
    settings, art = solved
    cov = art.stdev.covariance
    # k4 is not in the artifact's 5-coefficient model (an artifact from elsewhere, hash and all)
    swapped = cov.model_copy(update={"parameters": [*cov.parameters[:-1], "k4"]})
    bad = art.model_copy(
        update={"stdev": art.stdev.model_copy(update={"covariance": swapped}), "content_sha256": UNSEALED}
    )
    with Store.open(settings.db_url) as store:
        stored = store.add_artifact(bad, activate=False, actor="t", station="s", reason="foreign")
    with pytest.raises(InputError, match="does not fit") as err:
        report_workflow.write_report(settings, stored.ref, tmp_path / "r.html", force=False)
    assert err.value.exit_code == 2 and not (tmp_path / "r.html").exists()
