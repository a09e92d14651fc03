"""The camera-IMU report section of a result stored before the plotted series existed: its tables, and a
line saying how to draw the plots; such a result dumps (and hashes) without the new fields. A solved IMU
model gets a table of its states."""

from __future__ import annotations

from calibctl.workflows.imu.imu_report import imu_section
from tests.artifacts.test_imu_contract import imu_estimate, imu_model_estimate, imu_result


def test_a_result_stored_without_series_keeps_its_hash_and_says_how_to_draw_them() -> None:
    ev = imu_result()
    dumped = ev.model_dump(mode="json")
    assert "row_test" not in dumped and "series" not in dumped
    html = imu_section([ev])
    assert (
        'data-key="imu_td_imu-CAM-0001">12.0000<' in html
        and 'data-key="imu_sigma_td_imu-CAM-0001">0.1000<' in html
    )
    assert 'data-key="imu_plots_missing_imu-CAM-0001"' in html and "<svg" not in html
    assert imu_section([]) == ""


def test_a_solved_imu_model_is_tabled_with_its_sigma_and_the_calibrated_imu_has_no_table() -> None:
    assert 'data-key="imu_model_imu-CAM-0001"' not in imu_section([imu_result()])
    ev = imu_result(imu_estimate().model_copy(update={"imu_model": imu_model_estimate()}))
    html = imu_section([ev])
    assert 'data-key="imu_model_imu-CAM-0001">scale-misalignment<' in html
    assert 'data-key="imu_model_imu-CAM-0001_mg_xx">0.001000<' in html
    assert 'data-key="imu_model_sigma_imu-CAM-0001_mg_xx">0.000500<' in html
