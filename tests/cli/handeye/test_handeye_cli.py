"""`calibctl handeye` / `synth-motions` on motion logs: wiring, gates (exit 1), bad input (exit 2),
outputs."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from calibctl.artifacts.handeye import HandEyeResult
from calibctl.cli.main import app
from calibctl.core.extrinsics import se3

RUNNER = CliRunner()
TRUTH_T_M = np.array([0.12, -0.05, 0.30])


def invoke(*args: str):
    return RUNNER.invoke(app, list(args), terminal_width=110)


def synth(path: Path, *extra: str) -> Path:
    result = invoke("synth-motions", str(path), "--seed", "1", *extra)
    assert result.exit_code == 0, result.output
    return path


def handeye(path: Path, *extra: str):
    return invoke("handeye", str(path), "--from", "lidar", "--to", "camera", *extra)


def rewrite(src: Path, dst: Path, edit) -> Path:
    """Copy a CSV, applying ``edit(row_index, row_dict)`` to every data row."""
    with src.open() as handle:
        rows = list(csv.DictReader(handle))
    for i, row in enumerate(rows):
        edit(i, row)
    with dst.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return dst


def test_synth_then_solve_recovers_x_within_its_sigma_and_writes_json_and_tf_static(tmp_path: Path) -> None:
    log = synth(tmp_path / "m.csv")
    truth = json.loads((tmp_path / "m.truth.json").read_text())
    np.testing.assert_allclose(truth["translation_m"], TRUTH_T_M)
    result = handeye(log, "-o", str(tmp_path / "r.json"), "--tf-static", str(tmp_path / "tf.yaml"))
    assert result.exit_code == 0, result.output
    assert "Result: ACCEPTED" in result.stdout and "T_lidar_camera:" in result.stdout
    doc = HandEyeResult.model_validate_json((tmp_path / "r.json").read_text())
    assert doc.status == "accepted" and doc.content_sha256 == doc.computed_sha256()
    assert (
        doc.parent_frame == "lidar" and doc.child_frame == "camera" and doc.provenance.input_shape == "poses"
    )
    assert doc.refinement == "poses"
    assert doc.transform is not None and doc.uncertainty is not None
    error_mm = (np.array(doc.transform.translation_m) - TRUTH_T_M) * 1e3
    assert np.all(np.abs(error_mm) < 4 * np.array(doc.uncertainty.sigma_translation_mm))
    R = se3.rotation_from_quaternion(np.array(doc.transform.rotation_wxyz))
    assert np.degrees(se3.rotation_angle_rad(R.T @ np.array(truth["T_a_b"])[:3, :3])) < 0.2
    tf = yaml.safe_load((tmp_path / "tf.yaml").read_text())["transforms"][0]
    assert tf["header"]["frame_id"] == "lidar" and tf["child_frame_id"] == "camera"
    assert tf["transform"]["translation"]["z"] == pytest.approx(doc.transform.translation_m[2])
    assert tf["transform"]["rotation"]["w"] == pytest.approx(doc.transform.rotation_wxyz[0])


def test_json_output_is_the_result_document(tmp_path: Path) -> None:
    result = handeye(synth(tmp_path / "m.csv"), "--json", "--method", "tsai")
    assert result.exit_code == 0, result.output
    doc = HandEyeResult.model_validate(json.loads(result.stdout))
    assert doc.method == "tsai" and len(doc.motions) == 29 and doc.motions[0].label == "lines 2-3"


def test_motions_input_shape(tmp_path: Path) -> None:
    log = synth(tmp_path / "m.csv", "--shape", "motions", "--rows", "12", "--amplitude-deg", "60")
    result = handeye(log, "--input", "motions", "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["provenance"]["input_shape"] == "motions" and doc["refinement"] == "motions"


def test_corridor_is_refused_with_the_seed_message_and_no_transform(tmp_path: Path) -> None:
    log = synth(tmp_path / "c.csv", "--excitation", "corridor")
    result = handeye(log, "-o", str(tmp_path / "r.json"), "--tf-static", str(tmp_path / "tf.yaml"))
    assert result.exit_code == 1, result.output
    assert "Result: REJECTED (no transform reported)" in result.stdout
    doc = HandEyeResult.model_validate_json((tmp_path / "r.json").read_text())
    assert doc.status == "rejected" and doc.transform is None and doc.uncertainty is None
    lever = next(g for g in doc.gates if g.gate == "lever-arm")
    assert lever.message == (
        "lever arm unobservable: sigma_min 0.008 (about 0.5 deg of rotation); "
        "rotate at least 30 deg about two non-parallel axes"
    )
    assert "lever arm unobservable: " in result.stdout
    assert not (tmp_path / "tf.yaml").exists() and "not written" in result.stdout


def test_a_stricter_lever_arm_gate_from_the_command_line(tmp_path: Path) -> None:
    result = handeye(synth(tmp_path / "m.csv"), "--lever-arm-sigma-min", "5.0")
    assert result.exit_code == 1 and "lever arm unobservable: sigma_min 1.3" in result.stdout


def test_a_time_offset_is_named(tmp_path: Path) -> None:
    result = handeye(synth(tmp_path / "t.csv", "--time-offset-ms", "80"))
    assert result.exit_code == 1
    assert "time alignment:" in result.stdout and "lines 15-16" in result.stdout


def _expect_input_error(result, *fragments: str) -> None:
    assert result.exit_code == 2, result.output
    for fragment in fragments:
        assert fragment in result.stderr, result.stderr
    assert "Traceback" not in result.output


def test_unnormalised_quaternion_names_the_line(tmp_path: Path) -> None:
    def scale(i, row):
        if i == 3:
            for c in "wxyz":
                row[f"b_q{c}"] = str(float(row[f"b_q{c}"]) * 1.04)

    bad = rewrite(synth(tmp_path / "m.csv"), tmp_path / "bad.csv", scale)
    _expect_input_error(handeye(bad), "bad.csv: b quaternion not normalised at line 5", "norm 1.0400")


def test_non_orthonormal_rotation_matrix_names_the_line(tmp_path: Path) -> None:
    src = synth(tmp_path / "m.csv")

    def to_matrix(i, row):
        R = se3.rotation_from_quaternion(np.array([float(row.pop(f"a_q{c}")) for c in "wxyz"]))
        if i == 2:
            R[0, 0] += 0.01
        row.update({f"a_r{r + 1}{c + 1}": repr(float(R[r, c])) for r in range(3) for c in range(3)})

    bad = rewrite(src, tmp_path / "bad.csv", to_matrix)
    _expect_input_error(handeye(bad), "a rotation matrix not orthonormal at line 4")
    good = rewrite(src, tmp_path / "good.csv", lambda i, row: to_matrix(-1, row))
    assert handeye(good).exit_code == 0


def test_millimetres_where_metres_are_expected(tmp_path: Path) -> None:
    def to_mm(i, row):
        for c in "xyz":
            row[f"a_t{c}_m"] = str(float(row[f"a_t{c}_m"]) * 1000)

    bad = rewrite(synth(tmp_path / "m.csv"), tmp_path / "mm.csv", to_mm)
    _expect_input_error(handeye(bad), "a's translations look like millimetres")


def _tool_point_log(path: Path) -> tuple[Path, np.ndarray]:
    """Poses of an arm that mostly turns about its own tool point (a's translation unchanged), as the
    real RWHE-Calib kuka_2 log does, with a camera 0.14 m off that point; b = a's pose times X (Y = I)."""
    X = se3.transform(
        se3.rotation_from_rotvec(np.radians([3.0, -2.0, 88.0])), np.array([0.014, -0.108, -0.082])
    )
    rng = np.random.default_rng(7)
    T = se3.transform(np.eye(3), np.array([-0.57, 1.13, 0.61]))
    poses = [T]
    for i in range(18):
        step = se3.transform(
            se3.rotation_from_rotvec(rng.normal(size=3) * np.radians(12.0)),
            rng.normal(size=3) * (0.06 if i % 3 == 2 else 2e-6),
        )  # the controller's micrometres
        T = T @ step
        poses.append(T)
    columns = [
        "a_qw",
        "a_qx",
        "a_qy",
        "a_qz",
        "a_tx_m",
        "a_ty_m",
        "a_tz_m",
        "b_qw",
        "b_qx",
        "b_qy",
        "b_qz",
        "b_tx_m",
        "b_ty_m",
        "b_tz_m",
    ]
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        for T_wa_a in poses:
            T_wb_b = T_wa_a @ X
            writer.writerow(
                [
                    repr(float(v))
                    for v in (
                        *se3.quaternion_from_rotation(T_wa_a[:3, :3]),
                        *T_wa_a[:3, 3],
                        *se3.quaternion_from_rotation(T_wb_b[:3, :3]),
                        *T_wb_b[:3, 3],
                    )
                ]
            )
    return path, X


def test_an_arm_turning_about_its_tool_point_is_not_taken_for_millimetres(tmp_path: Path) -> None:
    # Two of three motions turn a about its own origin: a moves micrometres while b, on a 0.14 m lever
    # arm, moves centimetres; the median translation ratio is ~1e-4, which is no unit error.
    log, X = _tool_point_log(tmp_path / "tcp.csv")
    result = handeye(log, "--json")
    assert result.exit_code == 0, result.output
    got = json.loads(result.stdout)["transform"]["translation_m"]
    np.testing.assert_allclose(got, X[:3, 3], atol=1e-4)


def test_millimetres_hidden_by_pure_rotations_are_refused_by_the_translation_scale_gate(
    tmp_path: Path,
) -> None:
    # a's translations in mm: the arm's tool-point turns move it millimetres, the camera centimetres, so
    # the median ratio looks like no unit error and the log was accepted with a lever arm of tens of
    # metres. The translation half of A X = X B with a free scale on a gives 0.001: refused, unit named.
    log, _ = _tool_point_log(tmp_path / "tcp.csv")

    def to_mm(i, row):
        row.update({c: repr(float(row[c]) * 1000) for c in ("a_tx_m", "a_ty_m", "a_tz_m")})

    result = handeye(rewrite(log, tmp_path / "tcp_mm.csv", to_mm), "--json")
    assert result.exit_code == 1, result.output
    doc = HandEyeResult.model_validate(json.loads(result.stdout))
    assert doc.status == "rejected" and doc.transform is None
    failed = [g for g in doc.gates if not g.passed]
    assert [g.gate for g in failed] == ["translation-scale"]
    assert failed[0].value == pytest.approx(1000.0, rel=0.01)
    assert "lidar's translations look like millimetres, not metres" in failed[0].message
    clean = json.loads(handeye(log, "--json").stdout)["gates"]
    assert next(g for g in clean if g["gate"] == "translation-scale")["value"] == pytest.approx(1.0, abs=1e-3)


def test_rotation_vector_in_degrees(tmp_path: Path) -> None:
    def to_rotvec_deg(i, row):
        q = np.array([float(row.pop(f"b_q{c}")) for c in "wxyz"])
        v = np.degrees(se3.rotvec_from_rotation(se3.rotation_from_quaternion(q))) + (10.0 if i == 5 else 0.0)
        row.update({f"b_r{c}_rad": repr(float(x)) for c, x in zip("xyz", v, strict=True)})

    bad = rewrite(synth(tmp_path / "m.csv"), tmp_path / "deg.csv", to_rotvec_deg)
    _expect_input_error(handeye(bad), "b rotation vector longer than a full turn", "degrees where radians")


def test_unsynchronised_rows_are_named(tmp_path: Path) -> None:
    def split(i, row):
        row["a_t_s"] = row["t_s"]
        row["b_t_s"] = str(float(row.pop("t_s")) + (0.040 if i in (4, 9) else 0.001))

    bad = rewrite(synth(tmp_path / "m.csv"), tmp_path / "sync.csv", split)
    _expect_input_error(handeye(bad), "unsynchronised rows", "lines 6, 11", "40.0 ms")
    assert handeye(bad, "--max-skew-ms", "50").exit_code == 0


def test_too_few_poses(tmp_path: Path) -> None:
    src = synth(tmp_path / "m.csv")
    lines = src.read_text().splitlines()
    short = tmp_path / "short.csv"
    short.write_text("\n".join(lines[:3]) + "\n")
    _expect_input_error(handeye(short), "short.csv has 2 pose rows, i.e. 1 motion(s)")


def test_missing_rotation_and_missing_file(tmp_path: Path) -> None:
    bad = rewrite(
        synth(tmp_path / "m.csv"), tmp_path / "norot.csv", lambda i, row: [row.pop(f"a_q{c}") for c in "wxyz"]
    )
    _expect_input_error(handeye(bad), "no complete rotation for a")
    _expect_input_error(handeye(tmp_path / "absent.csv"), "does not exist")


def test_usage_errors(tmp_path: Path) -> None:
    log = synth(tmp_path / "m.csv")
    _expect_input_error(
        invoke("handeye", str(log), "--from", "cam", "--to", "cam"), "--from and --to are both 'cam'"
    )
    _expect_input_error(handeye(log, "--method", "horaud"), "unknown method 'horaud'")
    _expect_input_error(handeye(log, "--input", "twists"), "unknown --input 'twists'")
    _expect_input_error(
        invoke("handeye", str(log), "--from", "bad frame", "--to", "cam"), "'bad frame' is not a frame name"
    )


def test_synth_motions_refuses_to_overwrite_and_bad_options(tmp_path: Path) -> None:
    log = synth(tmp_path / "m.csv")
    _expect_input_error(invoke("synth-motions", str(log)), "exists")
    _expect_input_error(
        invoke("synth-motions", str(tmp_path / "x.csv"), "--excitation", "zigzag"), "unknown --excitation"
    )
    _expect_input_error(
        invoke("synth-motions", str(tmp_path / "y.csv"), "--shape", "motions", "--time-offset-ms", "5"),
        "a time offset needs a pose log",
    )


def test_same_seed_same_bytes(tmp_path: Path) -> None:
    assert synth(tmp_path / "a.csv").read_bytes() == synth(tmp_path / "b.csv").read_bytes()


def test_two_rotation_forms_for_one_sensor_are_refused(tmp_path: Path) -> None:
    def add_rotvec(i, row):
        q = np.array([float(row[f"a_q{c}"]) for c in "wxyz"])
        v = se3.rotvec_from_rotation(se3.rotation_from_quaternion(q))
        row.update({f"a_r{c}_rad": repr(float(x)) for c, x in zip("xyz", v, strict=True)})

    bad = rewrite(synth(tmp_path / "m.csv"), tmp_path / "both.csv", add_rotvec)
    _expect_input_error(handeye(bad), "more than one complete rotation for a (quaternion, rotvec)")


def test_half_a_timestamp_pair_and_unsorted_times(tmp_path: Path) -> None:
    src = synth(tmp_path / "m.csv")
    half = rewrite(src, tmp_path / "half.csv", lambda i, row: row.update(a_t_s=row.pop("t_s")))
    _expect_input_error(handeye(half), "give both a_t_s and b_t_s")

    def swap(i, row):
        if i == 6:
            row["t_s"] = "0.1"

    _expect_input_error(
        handeye(rewrite(src, tmp_path / "unsorted.csv", swap)), "t_s does not increase at line 8"
    )


def test_one_relative_motion_is_too_few(tmp_path: Path) -> None:
    log = synth(tmp_path / "m.csv", "--shape", "motions", "--rows", "4")
    one = tmp_path / "one.csv"
    one.write_text("\n".join(log.read_text().splitlines()[:2]) + "\n")
    _expect_input_error(handeye(one, "--input", "motions"), "one.csv has 1 motion; hand-eye needs at least 2")


def test_outputs_are_never_overwritten_without_force(tmp_path: Path) -> None:
    log = synth(tmp_path / "m.csv")
    (tmp_path / "r.json").write_text("keep me")
    _expect_input_error(handeye(log, "-o", str(tmp_path / "r.json")), "exists")
    assert (tmp_path / "r.json").read_text() == "keep me"
    assert handeye(log, "-o", str(tmp_path / "r.json"), "--force").exit_code == 0
    _expect_input_error(handeye(log, "-o", str(tmp_path / "no-such-dir" / "r.json")), "does not exist")


def test_a_diverged_refinement_is_exit_2_not_a_traceback(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from calibctl.workflows.handeye import handeye as wf

    real = wf.fit_handeye

    def diverged(motions, method):
        fit = real(motions, method)
        return dataclasses.replace(fit, T_a_b=np.full((4, 4), np.nan))

    monkeypatch.setattr(wf, "fit_handeye", diverged)
    _expect_input_error(handeye(synth(tmp_path / "m.csv")), "the hand-eye refinement diverged")


def test_poses_given_the_wrong_way_round_are_rejected_as_inconsistent(tmp_path: Path) -> None:
    def invert_b(i, row):
        q = np.array([float(row[f"b_q{c}"]) for c in "wxyz"])
        T = se3.invert(
            se3.transform(se3.rotation_from_quaternion(q), np.array([float(row[f"b_t{c}_m"]) for c in "xyz"]))
        )
        q_inv = se3.quaternion_from_rotation(T[:3, :3])
        row.update({f"b_q{c}": repr(float(v)) for c, v in zip("wxyz", q_inv, strict=True)})
        row.update({f"b_t{c}_m": repr(float(v)) for c, v in zip("xyz", T[:3, 3], strict=True)})

    bad = rewrite(synth(tmp_path / "m.csv"), tmp_path / "inverted.csv", invert_b)
    result = handeye(bad, "--json")
    assert result.exit_code == 1
    doc = HandEyeResult.model_validate(json.loads(result.stdout))
    assert doc.status == "rejected" and doc.transform is None
    assert [g.gate for g in doc.gates if not g.passed] == ["consistency"]
    assert doc.motions[0].residual_rotation_deg is not None  # the residuals stay in the record
