"""The camera-IMU room on a rendered recording: every bad input refused (exit 2, one message naming the
file and the fix, nothing stored), the solve pinned to the camera's stored calibration, the evidence
stored as the rig's next version at full precision, a degenerate motion never active, a stale edge
named by lint and dropped by the next write."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calibctl.errors import CalibctlError
from calibctl.store.repository import Store
from calibctl.workflows.edges import versions
from calibctl.workflows.imu import imu_solve
from calibctl.workflows.imu import recording as recording_module
from tests.artifacts.factories import calibration, measured_board
from tests.store.rig_documents import RIG
from tests.workflows.imu.imu_data import (
    CAM,
    OTHER,
    TD_S,
    WHO,
    copy_db,
    copy_recording,
    make_store,
    rendered,
    settings_for,
    truth,
)


def _rewrite(path: Path, edit) -> None:
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n")


def _scale_columns(lines: list[str], cols: slice, factor: float) -> list[str]:
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        cells[cols] = [f"{float(c) * factor:.9f}" for c in cells[cols]]
        out.append(",".join(cells))
    return out


def _swap_rows(lines: list[str]) -> list[str]:
    return [lines[0], lines[2], lines[1], *lines[3:]]


def _shift_stamps(lines: list[str]) -> list[str]:
    return [lines[0]] + [f"{int(x.split(',', 1)[0]) + 10**12},{x.split(',', 1)[1]}" for x in lines[1:]]


def _deg_header(lines: list[str]) -> list[str]:
    return [lines[0].replace("rad s^-1", "deg s^-1"), *lines[1:]]


def _g_header(lines: list[str]) -> list[str]:
    return [lines[0].replace("m s^-2", "g"), *lines[1:]]


IMU_EDITS = {
    "gyro header in deg/s": (_deg_header, "imu0/data.csv: the gyro columns are in deg/s", "pi/180"),
    "accel header in g": (_g_header, "imu0/data.csv: the accelerometer columns are in g", "9.80665"),
    "gyro numbers in deg/s": (
        lambda lines: _scale_columns(lines, slice(1, 4), 180 / np.pi),
        "the gyro reads deg/s; multiply by pi/180",
        None,
    ),
    "accel numbers in g": (
        lambda lines: _scale_columns(lines, slice(4, 7), 1 / 9.80665),
        "it reads g; multiply by 9.80665",
        None,
    ),
    "stamps not increasing": (_swap_rows, "imu0/data.csv: stamps do not increase at line 3", "sort the log"),
    "logs that do not overlap": (_shift_stamps, "do not overlap in time", "one clock"),
}


@pytest.mark.parametrize("case", IMU_EDITS, ids=list(IMU_EDITS))
def test_a_bad_imu_log_is_exit_2_naming_the_file_and_the_fix_and_nothing_is_stored(
    case, recording, tmp_path
) -> None:
    edit, message, hint = IMU_EDITS[case]
    rec = copy_recording(recording, tmp_path)
    _rewrite(rec / "imu0" / "data.csv", edit)
    url = make_store(tmp_path / "c.db")
    req = imu_solve.ImuRequest(rec, CAM, rig=RIG)
    with pytest.raises(CalibctlError) as info:
        imu_solve.run_imu(settings_for(url), req)
    err = info.value
    assert err.exit_code == 2 and message in str(err) and "imu0" in err.message
    assert hint is None or hint in (err.hint or "")
    with Store.open(url) as store:
        assert [c.version for c in store.list_rig_calibrations(RIG)] == [1]


@pytest.mark.parametrize(
    ("order", "message"),
    [
        ([0, 0, 1, 2], r"cam0/data.csv: frame stamp \d+ is listed twice"),
        ([0, 2, 1, 3], r"cam0/data.csv: frame stamp \d+ \(data line 3\) is before \d+ \(data line 2\)"),
    ],
    ids=["listed twice", "out of order"],
)
def test_a_camera_stamp_listed_twice_or_out_of_order_is_refused_naming_the_list(
    recording, tmp_path, order, message
) -> None:
    rec = copy_recording(recording, tmp_path)
    stamps = sorted(p.stem for p in (rec / "cam0").glob("*.csv"))
    listing = ["#timestamp [ns],filename"] + [f"{stamps[i]},{stamps[i]}.png" for i in order]
    (rec / "cam0" / "data.csv").write_text("\n".join(listing) + "\n")
    url = make_store(tmp_path / "c.db")
    with pytest.raises(CalibctlError, match=message) as info:
        imu_solve.run_imu(settings_for(url), imu_solve.ImuRequest(rec, CAM))
    assert info.value.exit_code == 2


def test_an_existing_result_file_is_refused_before_anything_is_stored(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    (tmp_path / "out.json").write_text("{}")
    req = imu_solve.ImuRequest(recording, CAM, rig=RIG, out=tmp_path / "out.json")
    with pytest.raises(CalibctlError, match="out.json already exists; nothing was solved or stored") as info:
        imu_solve.run_imu(settings_for(url), req)
    assert info.value.exit_code == 2 and "--force" in (info.value.hint or "")
    with Store.open(url) as store:
        assert [c.version for c in store.list_rig_calibrations(RIG)] == [1]


def test_a_corner_file_whose_rows_name_another_stamp_is_refused(recording, tmp_path) -> None:
    rec = copy_recording(recording, tmp_path)
    first = sorted((rec / "cam0").glob("*.csv"))[0]
    other = int(first.stem) + 1
    _rewrite(first, lambda lines: [lines[0]] + [f"{other},{x.split(',', 1)[1]}" for x in lines[1:]])
    with pytest.raises(CalibctlError, match=f"named {first.stem} but its rows are stamped {other}"):
        recording_read(rec)


def recording_read(rec: Path) -> recording_module.Recording:
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    return recording_module.read_recording(rec, "cam0", (K, np.zeros(5), (640, 480)))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("gyroscope_noise_density: 1.0e-4\n", "not a Kalibr imu.yaml"),
        (
            "gyroscope_noise_density: -1.0e-4\naccelerometer_noise_density: 2.0e-3\n"
            "gyroscope_random_walk: 1e-05\naccelerometer_random_walk: 1e-4\n",
            "must be a positive number",
        ),
        (
            "gyroscope_noise_density: fast\naccelerometer_noise_density: 2.0e-3\n"
            "gyroscope_random_walk: 1e-05\naccelerometer_random_walk: 1e-4\n",
            "gyroscope_noise_density = 'fast' is not a number",
        ),
    ],
)
def test_a_bad_noise_file_is_refused_naming_the_field(tmp_path, text, message) -> None:
    path = tmp_path / "imu.yaml"
    path.write_text(text)
    with pytest.raises(CalibctlError, match=message) as info:
        recording_module.read_noise(path)
    assert info.value.exit_code == 2 and str(path) in info.value.message


def test_kalibr_and_yac_noise_files_read_alike(recording, tmp_path) -> None:
    kalibr, source = recording_module.read_noise(recording / "imu.yaml")
    assert source == str(recording / "imu.yaml")
    yac = tmp_path / "config.yaml"
    yac.write_text(
        "imu0:\n"
        + "".join(
            f"  {key}: {getattr(kalibr, field)!r}\n" for key, field in recording_module.YAC_NOISE.items()
        )
        + "  g: 9.81007\n"
    )
    again, _ = recording_module.read_noise(yac)
    assert again == kalibr.__class__(**{**kalibr.__dict__, "gravity_m_s2": 9.81007})
    assert recording_module.read_noise(None) == (recording_module.DEFAULT_NOISE, "defaults")


def test_a_recording_without_an_imu_log_or_corners_is_refused(recording, tmp_path) -> None:
    rec = copy_recording(recording, tmp_path)
    (rec / "imu0" / "data.csv").rename(rec / "imu0" / "other.csv")
    with pytest.raises(CalibctlError, match=r"no IMU log \(imu0/data.csv or imu0.csv\)"):
        recording_read(rec)
    (rec / "imu0" / "other.csv").rename(rec / "imu0" / "data.csv")
    (tmp_path / "MH_01").mkdir()
    rec = rec.rename(tmp_path / "MH_01" / "mav0")  # EuRoC's zip unpacked: the layout one folder down
    with pytest.raises(CalibctlError, match="EuRoC's layout keeps it in mav0/") as info:
        recording_read(tmp_path / "MH_01")
    assert info.value.hint == f"give the recording folder {rec}"
    (rec / "imu0" / "data.csv").rename(rec / "imu0.csv")  # yac's name for the same log
    with pytest.raises(CalibctlError, match="cam1: no such camera folder"):
        recording_module.read_recording(rec, "cam1", (np.eye(3), np.zeros(5), (640, 480)))


def test_the_camera_needs_an_active_calibration_and_a_rig_member(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db", other_calibrated=False)
    s = settings_for(url)
    with pytest.raises(CalibctlError, match=f"camera {OTHER} has no active calibration") as info:
        imu_solve.run_imu(s, imu_solve.ImuRequest(recording, OTHER))
    assert info.value.exit_code == 2
    with pytest.raises(CalibctlError, match="camera CAM-0009 is not a member of rig"):
        imu_solve.run_imu(s, imu_solve.ImuRequest(recording, "CAM-0009", rig=RIG))
    with pytest.raises(CalibctlError, match="--imu-frame 'imu-0' is not a legal ROS frame name"):
        imu_solve.run_imu(s, imu_solve.ImuRequest(recording, CAM, rig=RIG, imu_frame="imu-0"))
    with pytest.raises(CalibctlError, match="frame 'gyro' is not in rig"):
        imu_solve.run_imu(s, imu_solve.ImuRequest(recording, CAM, rig=RIG, imu_frame="gyro"))


def test_the_stored_edge_carries_the_truth_within_its_sigma_at_full_precision(solved, recording) -> None:
    db, doc = solved
    t = truth(recording)
    assert doc["version"] == 2 and doc["status"] == "accepted"
    (ev,) = doc["imu"]
    est = ev["estimate"]
    assert ev["camera"] == f"{CAM}@1" and ev["parent_frame"] == "imu" and ev["child_frame"] == CAM
    assert abs(est["td_s"] - TD_S) < 5 * est["sigma_td_ms"] / 1e3
    dt_mm = 1e3 * np.abs(np.array(est["T_imu_cam"])[:3, 3] - np.array(t["T_imu_cam"])[:3, 3])
    assert np.all(dt_mm < 5 * np.array(est["sigma_translation_mm"]))
    assert len(est["covariance"]) == 7 and est["covariance"][6][6] == pytest.approx(
        (est["sigma_td_ms"] / 1e3) ** 2, rel=1e-6
    )
    edge = next(e for e in doc["edges"] if e["source"] == "camera-imu")
    assert (edge["parent"], edge["child"]) == ("imu", CAM)
    assert edge["T_parent_child"] == est["T_imu_cam"]  # the tree edge is the evidence's, unrounded
    roles = [i["role"] for i in ev["inputs"]]
    assert roles == ["imu", "corners"] and all(len(i["sha256"]) == 64 for i in ev["inputs"])
    assert ev["noise"]["source"].endswith("imu.yaml") and ev["noise"]["rate_hz"] == pytest.approx(200.0)


def test_a_corridor_recording_is_a_rejected_version_never_active(tmp_path_factory, tmp_path) -> None:
    rec = rendered(tmp_path_factory, "corridor")
    url = make_store(tmp_path / "c.db")
    out = imu_solve.run_imu(settings_for(url), imu_solve.ImuRequest(rec, CAM, rig=RIG))
    assert not out.accepted and out.stored is not None and out.stored.status == "rejected"
    failed = [g.gate for g in out.stored.imu[0].gates if not g.passed]
    assert "td_rotation_correlation" in failed or "td_observability" in failed
    assert not [e for e in out.stored.edges if e.source == "camera-imu"]
    with Store.open(url) as store:
        assert store.get_rig_calibration(RIG, None).version == 1
    # held at a known td, the extrinsic is estimated alone and the hold named; a rotation about one
    # axis still cannot pin the extrinsic, so the version stays rejected
    held = imu_solve.run_imu(settings_for(url), imu_solve.ImuRequest(rec, CAM, rig=RIG, hold_td_s=TD_S))
    assert held.stored is not None and held.stored.status == "rejected"
    est = held.stored.imu[0].estimate
    assert est is not None and est.td_held and est.td_s == TD_S and est.sigma_td_ms == 0
    assert "td held at 12.000 ms" in (est.td_held_reason or "")
    assert "rotational_excitation" in [g.gate for g in held.stored.imu[0].gates if not g.passed]
    assert "td_rotation_correlation_free" not in [g.gate for g in held.stored.imu[0].gates]


def test_a_camera_recalibrated_since_makes_the_edge_stale_and_the_next_write_drops_it(solved, tmp_path):
    db, _ = solved
    url = copy_db(db, tmp_path)
    with Store.open(url) as store:
        store.add_artifact(calibration(serial=CAM, fx=801.0), activate=True, **WHO)  # CAM-0001@2
        active = store.get_rig_calibration(RIG, None)
        now = versions.cal_versions(store, active)
    findings = versions.edge_findings(active.imu, now)
    assert [f.rule for f in findings] == ["imu-stale-member"] and "solved with CAM-0001@1" in findings[
        0
    ].message
    kept = versions.carried_forward(active, now)
    assert kept.evidence["imu"] == [] and [f.rule for f in kept.dropped] == ["imu-dropped"]


def test_corner_files_of_another_board_are_refused_naming_the_board(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    req = imu_solve.ImuRequest(recording, CAM, board="G7-40")
    wrong = r"m is no corner of board G7-40@1 \(\d+\.\d mm from the nearest\)"
    with pytest.raises(CalibctlError, match=wrong) as info:
        imu_solve.run_imu(settings_for(url), req)
    assert info.value.exit_code == 2 and "name the board these corners were detected on" in (
        info.value.hint or ""
    )


def test_asl_images_are_detected_with_the_registered_board(tmp_path_factory, tmp_path) -> None:
    rec = rendered(tmp_path_factory, "images")
    assert not list((rec / "cam0").glob("*.csv"))[1:]  # data.csv alone: the corners are in the images
    url = make_store(tmp_path / "c.db")
    s = settings_for(url)
    with pytest.raises(CalibctlError, match="holds images \\(data.csv\\), not corner files") as info:
        imu_solve.run_imu(s, imu_solve.ImuRequest(rec, CAM))
    assert info.value.exit_code == 2 and "--board" in (info.value.hint or "")
    with Store.open(url) as store:
        store.add_board(measured_board("B9"))  # 9 x 6 inner corners: not the board the images show
    with pytest.raises(
        CalibctlError, match=r"cam0/data: board B9@1 is found in none of the 60 images"
    ) as info:
        imu_solve.run_imu(s, imu_solve.ImuRequest(rec, CAM, rig=RIG, board="B9"))
    assert info.value.exit_code == 2 and "--board" in (info.value.hint or "")
    out = imu_solve.run_imu(s, imu_solve.ImuRequest(rec, CAM, noise=rec / "imu.yaml", rig=RIG, board="G7"))
    assert out.stored is not None and out.stored.status == "accepted"
    ev = out.stored.imu[0]
    assert ev.board == "G7@1" and [i.role for i in ev.inputs] == ["imu", "camera", "images"]
    assert ev.estimate is not None and abs(ev.estimate.td_s - TD_S) < 5 * ev.estimate.sigma_td_ms / 1e3


def test_a_fisheye_calibration_is_refused_naming_the_model(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    art = calibration(serial=CAM, fx=801.0)
    fisheye = art.model_copy(update={"model": art.model.model_copy(update={"name": "fisheye"})}).sealed()
    with Store.open(url) as store:
        store.add_artifact(fisheye, activate=True, **WHO)
    with pytest.raises(CalibctlError, match=f"camera {CAM}@2 is calibrated with the fisheye model") as info:
        imu_solve.run_imu(settings_for(url), imu_solve.ImuRequest(recording, CAM))
    assert info.value.exit_code == 2 and "pinhole model" in (info.value.hint or "")
