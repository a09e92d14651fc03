"""`calibctl imu` end to end on a rendered recording: synth -> solve --rig -> rig show / export -> lint
passes; Kalibr's camchain carries td as timeshift_cam_imu; an edited number in the stored edge is refused
by lint and import; bad input is exit 2 in one line; a degenerate motion is exit 1 and never active."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from tests.store.rig_documents import RIG
from tests.workflows.imu.imu_data import (
    CAM,
    TD_S,
    cli,
    copy_db,
    copy_recording,
    make_store,
    rendered,
    truth,
)


def _yaml_body(text: str) -> dict:
    return yaml.safe_load("\n".join(x for x in text.splitlines() if not x.startswith("#")))


def test_help_names_the_inputs() -> None:
    r = cli("sqlite://", "imu", "solve", "--help")
    assert r.exit_code == 0
    for word in ("imu0/data.csv", "<ns>.csv", "--serial", "--noise", "imu.yaml", "--hold-td-ms", "--rig"):
        assert word in r.output


def test_synth_solve_json_is_the_truth_within_its_sigma(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    out = tmp_path / "o.json"
    r = cli(
        url,
        "imu",
        "solve",
        str(recording),
        "--serial",
        CAM,
        "--noise",
        str(recording / "imu.yaml"),
        "--json",
        "-o",
        str(out),
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert json.loads(out.read_text()) == doc  # -o holds what --json prints
    e = doc["estimate"]
    assert doc["status"] == "accepted" and doc["camera"] == f"{CAM}@1" and "stored" not in doc
    assert abs(e["td_ms"] - TD_S * 1e3) < 5 * e["sigma_td_ms"]
    assert e["timeshift_cam_imu_s"] == pytest.approx(e["td_ms"] / 1e3, abs=1e-6)
    assert np.allclose(np.array(e["T_cam_imu"]) @ np.array(e["matrix"]), np.eye(4), atol=1e-6)
    t = truth(recording)
    assert np.allclose(np.array(e["T_cam_imu"])[:3, :3], np.array(t["T_cam_imu"])[:3, :3], atol=2e-3)


def test_the_stored_edge_shows_exports_and_lints_clean(solved, tmp_path) -> None:
    db, doc = solved
    url = copy_db(db, tmp_path)
    (ev,) = doc["imu"]
    td = ev["estimate"]["td_s"]
    shown = cli(url, "rig", "show", RIG)
    assert shown.exit_code == 0 and "(camera-imu)" in shown.stdout
    assert f"imu imu -> {CAM}: accepted, td {td * 1e3:+.3f} ms" in shown.stdout
    history = json.loads(cli(url, "rig", "history", RIG, "--json").stdout)
    assert history["versions"][-1]["imu"] == [{"edge": f"imu:{CAM}", "status": "accepted"}]
    assert cli(url, "rig", "lint", RIG).exit_code == 0
    camchain = _yaml_body(cli(url, "rig", "export", RIG, "--format", "kalibr").stdout)
    T_cam_imu = np.linalg.inv(np.array(ev["estimate"]["T_imu_cam"]))
    assert np.allclose(camchain["cam0"]["T_cam_imu"], T_cam_imu, atol=1e-12)
    assert camchain["cam0"]["timeshift_cam_imu"] == td == camchain["cam1"]["timeshift_cam_imu"]
    imu_yaml = _yaml_body(cli(url, "rig", "export", RIG, "--format", "kalibr-imu").stdout)
    assert imu_yaml["gyroscope_noise_density"] == ev["noise"]["gyro_noise_density"]
    assert imu_yaml["rostopic"] == "/imu"
    tf = _yaml_body(cli(url, "rig", "export", RIG, "--edge", f"imu:{CAM}", "--format", "tf").stdout)
    assert tf["transforms"][0]["header"]["frame_id"] == "imu"
    bundle = tmp_path / "bundle"
    assert cli(url, "rig", "export", RIG, "--format", "bundle", "-o", str(bundle)).exit_code == 0
    assert (bundle / "imu.yaml").is_file()
    linted = cli(url, "lint", str(bundle / "manifest.json"))
    assert linted.exit_code == 0, linted.output
    assert "imu.yaml (kalibr-imu): pass" in linted.stdout and "camchain.yaml (kalibr): pass" in linted.stdout


def test_an_edited_number_in_the_stored_edge_is_refused_by_lint_and_import(solved, tmp_path) -> None:
    db, doc = solved
    url = copy_db(db, tmp_path)
    path = tmp_path / "rig.json"
    path.write_text(cli(url, "rig", "export", RIG, "--format", "json").stdout)
    assert cli(url, "lint", str(path)).exit_code == 0
    edited = json.loads(path.read_text())
    edited["imu"][0]["estimate"]["td_s"] += 0.001  # one millisecond later
    path.write_text(json.dumps(edited))
    linted = cli(url, "lint", str(path))
    assert linted.exit_code == 1 and "sha256" in linted.output
    imported = cli(url, "rig", "import", str(path))
    assert imported.exit_code == 1 and "content does not match its sha256" in imported.output


def test_a_gyro_in_deg_per_second_is_exit_2_in_one_line_naming_the_unit(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    rec = copy_recording(recording, tmp_path)
    log = rec / "imu0" / "data.csv"
    lines = log.read_text().splitlines()
    rows = [lines[0]]
    for line in lines[1:]:
        c = line.split(",")
        rows.append(",".join([c[0], *(f"{float(v) * 180 / np.pi:.6f}" for v in c[1:4]), *c[4:]]))
    log.write_text("\n".join(rows) + "\n")
    r = cli(url, "imu", "solve", str(rec), "--serial", CAM, "--rig", RIG)
    assert r.exit_code == 2 and len([x for x in r.output.splitlines() if x.startswith("Error:")]) == 1
    assert "the gyro reads deg/s; multiply by pi/180" in r.output and str(log) in r.output
    assert "Traceback" not in r.output
    assert json.loads(cli(url, "rig", "history", RIG, "--json").stdout)["versions"][-1]["version"] == 1


def test_a_corridor_is_exit_1_and_stored_as_a_rejected_version(tmp_path_factory, tmp_path) -> None:
    rec = rendered(tmp_path_factory, "corridor")
    url = make_store(tmp_path / "c.db")
    r = cli(url, "imu", "solve", str(rec), "--serial", CAM, "--rig", RIG)
    assert r.exit_code == 1, r.output
    assert "Result: REJECTED" in r.output and "(rejected, never active; no edge)" in r.output
    assert "excite with turns and reversals" in r.output
    history = json.loads(cli(url, "rig", "history", RIG, "--json").stdout)
    assert history["active_version"] == 1
    assert history["versions"][-1]["imu"] == [{"edge": f"imu:{CAM}", "status": "rejected"}]


def test_a_bag_without_rosbags_installed_names_the_bags_extra(monkeypatch, tmp_path) -> None:
    from tests.cli.app.test_extras_cli import _assert_missing_extra, _hide

    _hide(monkeypatch, "rosbags")
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    url = make_store(tmp_path / "c.db")
    args = ["--board", "G7", "--image-topic", "/cam0/image_raw", "--imu-topic", "/imu0"]
    res = cli(url, "imu", "solve", str(bag), "--serial", CAM, *args)
    _assert_missing_extra(res, "bags", "rosbags", "reading a ROS bag")


def test_the_rig_report_draws_the_imu_edge_from_the_store_byte_identical(solved, tmp_path) -> None:
    db, doc = solved
    url = copy_db(db, tmp_path)
    (ev,) = doc["imu"]
    e, k = ev["estimate"], f"imu-{CAM}"
    page = tmp_path / "rig.html"
    done = cli(url, "report", "--rig", RIG, "-o", str(page))
    assert done.exit_code == 0, done.output
    html = page.read_text()
    assert "<h2>Camera-IMU</h2>" in html and f'data-key="imu_status_{k}">accepted' in html
    for i, axis in enumerate("xyz"):
        assert f'data-key="imu_t_{k}_{axis}">{e["T_imu_cam"][i][3] * 1e3:.2f}<' in html
        assert f'data-key="imu_sigma_r_{k}_{axis}">{e["sigma_rotation_deg"][i]:.4f}<' in html
    assert f'data-key="imu_td_{k}">{e["td_s"] * 1e3:.4f}<' in html
    assert f'data-key="imu_sigma_td_{k}">{e["sigma_td_ms"]:.4f}<' in html
    assert f'data-key="imu_td_crlb_{k}">{e["td_crlb_ms"]:.4f}<' in html
    for gate in ev["gates"]:
        assert f'data-key="imu_gate_{k}_{gate["gate"]}">pass<' in html
    # a global-shutter render: the residuals do not ramp with the row
    assert f'data-key="imu_rolling_shutter_{k}">no<' in html and ev["row_test"]["message"] in html
    assert "gyro (lines) and camera rate (dots)" in html and "time residual over image rows" in html
    again = tmp_path / "again.html"
    assert cli(url, "report", "--rig", RIG, "-o", str(again)).exit_code == 0
    assert again.read_bytes() == page.read_bytes()
