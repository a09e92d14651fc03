"""The camera-IMU report section of a result stored before the plotted series existed: its tables, and a
line saying how to draw the plots; such a result dumps (and hashes) without the new fields."""

from __future__ import annotations

from calibctl.workflows.imu.imu_report import imu_section
from tests.artifacts.test_imu_contract import imu_result


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
