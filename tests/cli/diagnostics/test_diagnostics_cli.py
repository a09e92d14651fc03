"""calibctl triage / gauge / timeoffset / synth-residuals through the real CLI: exit codes and messages."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.workflows.diagnostics.diagnostics_io import write_table

runner = CliRunner()


def run(*args: str):
    return runner.invoke(app, [str(a) for a in args], env={"COLUMNS": "110"})


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("diag")
    for fault in ("time-offset", "gauge", "rotation"):
        res = run(
            "synth-residuals",
            d / f"{fault}.csv",
            "--fault",
            fault,
            "--seed",
            "2",
            "--keyframes",
            "150",
            "--cameras",
            "2" if fault == "rotation" else "1",
        )
        assert res.exit_code == 0, res.output
    return d


def _residual_csv(path: Path, n_rows: int = 40, **overrides) -> Path:
    rng = np.random.default_rng(0)
    cols = {
        "residual_px": rng.normal(0, 0.3, n_rows),
        "radius_px": rng.uniform(10, 500, n_rows),
        "image_speed_px_s": rng.uniform(50, 500, n_rows),
        "inv_range_per_m": rng.uniform(0.02, 1, n_rows),
        "row": rng.integers(0, 960, n_rows),
    }
    cols.update(overrides)
    write_table(path, cols, force=True)
    return path


def test_synth_reports_the_files_it_wrote(logs):
    res = run("synth-residuals", logs / "k1.csv", "--fault", "k1", "--keyframes", "20", "--json")
    assert res.exit_code == 0
    out = json.loads(res.stdout)
    assert out["schema"] == "calibctl.diagnostics.synth/1" and out["magnitude"] == 0.02
    assert all(Path(p).exists() for p in out["files"].values())


def test_triage_names_a_time_offset_and_exits_1(logs):
    res = run("triage", logs / "time-offset.csv")
    assert res.exit_code == 1
    assert "Verdict cam0: fault: camera time offset" in res.stdout
    assert "FAULT" in res.stdout and "ms" in res.stdout
    assert "Result: FAIL" in res.stdout


def test_triage_json_is_the_documented_dict(logs):
    for args in (
        ("triage", logs / "time-offset.csv", "--json"),
        ("--json", "triage", logs / "time-offset.csv"),
    ):
        res = run(*args)
        assert res.exit_code == 1
        out = json.loads(res.stdout)
        assert out["schema"] == "calibctl.diagnostics.triage/1" and out["verdict"] == "fail"
        td = next(c for c in out["cameras"][0]["channels"] if c["key"] == "time_offset")
        assert td["value"] == pytest.approx(0.0184, rel=0.05)


def test_triage_flags_the_rotation_degeneracy_and_the_bad_camera(logs):
    res = run("triage", logs / "rotation.csv")
    assert res.exit_code == 1
    assert "extrinsic rotation or principal point, these cannot be separated from this data" in res.stdout
    assert "principal point" in res.stdout and "max/min" in res.stdout and "ALARM" in res.stdout


def test_gauge_fault_triage_is_flat_and_the_gauge_alarms(logs):
    res = run("triage", logs / "gauge.csv")
    assert res.exit_code == 0
    assert "no residual signature" in res.stdout and "calibctl gauge" in res.stdout
    res = run("gauge", logs / "gauge_odometry.csv")
    assert res.exit_code == 1
    assert "ALARM" in res.stdout and "first alarm in the window starting at 0 s" in res.stdout
    assert "gauge error: a constant factor 1.0870" in res.stdout


def test_gauge_passes_on_slip_only(logs):
    res = run("gauge", logs / "time-offset_odometry.csv", "--json")
    assert res.exit_code == 0
    out = json.loads(res.stdout)
    assert out["level"] == "ok" and out["verdict"] == "pass"


def test_timeoffset_measures_td_with_its_uncertainty(logs, tmp_path):
    res = run(
        "timeoffset", logs / "time-offset_gyro.csv", logs / "time-offset_camera.csv", "--plot", tmp_path
    )
    assert res.exit_code == 0, res.output
    td_ms = float(re.search(r"td = ([+-][0-9.]+) ms \+/- ([0-9.]+) ms", res.stdout).group(1))
    assert td_ms == pytest.approx(18.4, abs=0.2) and "jackknife" in res.stdout
    assert "add td to camera timestamps" in res.stdout
    assert (tmp_path / "timeoffset.png").exists()


def test_timeoffset_refuses_a_constant_rate_with_exit_1(tmp_path):
    t = np.arange(0.0, 5.0, 0.005)
    rng = np.random.default_rng(1)
    for name in ("g.csv", "c.csv"):
        write_table(tmp_path / name, {"t_s": t, "rate_rad_s": 0.3 + rng.normal(0, 0.002, t.size)})
    res = run("timeoffset", tmp_path / "g.csv", tmp_path / "c.csv")
    assert res.exit_code == 1
    assert "REFUSED:" in res.stdout and "varies by only" in res.stdout
    out = json.loads(run("timeoffset", tmp_path / "g.csv", tmp_path / "c.csv", "--json").stdout)
    assert out["verdict"] == "refused" and out["td_s"] is None and "pin td" in out["reason"]


def test_plots_for_triage_and_gauge(logs, tmp_path):
    assert run("triage", logs / "rotation.csv", "--plot", tmp_path).exit_code == 1
    assert run("gauge", logs / "gauge_odometry.csv", "--plot", tmp_path).exit_code == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gauge.png", "triage_cam0.png", "triage_cam1.png"]


# ---- bad input: a clear message on stderr and exit 2, never a number --------------------------------


def _fails(res, *fragments: str) -> None:
    assert res.exit_code == 2, res.output
    assert res.stdout == ""
    for fragment in fragments:
        assert fragment in res.stderr, res.stderr


def test_missing_file(tmp_path):
    _fails(run("triage", tmp_path / "none.csv"), "Error: residual buffer", "does not exist")


def test_missing_columns_are_named(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("residual_px,radius_px,row\n1,2,3\n")
    _fails(run("triage", path), "missing column(s) image_speed_px_s, inv_range_per_m")


def test_non_numeric_and_non_finite_cells_give_line_numbers(tmp_path):
    path = _residual_csv(tmp_path / "r.csv")
    text = path.read_text().splitlines()
    text[3] = "oops," + text[3].split(",", 1)[1]
    path.write_text("\n".join(text) + "\n")
    _fails(run("triage", path), "column residual_px has non-numeric cells: line 4 ('oops')")
    text[3] = "nan," + text[3].split(",", 1)[1]
    text[7] = "inf," + text[7].split(",", 1)[1]
    path.write_text("\n".join(text) + "\n")
    _fails(run("triage", path), "non-finite values (nan/inf) at lines 4, 8")


def test_too_few_keyframes(tmp_path):
    path = _residual_csv(tmp_path / "r.csv", n_rows=40, keyframe=np.repeat(np.arange(5), 8))
    _fails(run("triage", path), "5 keyframes; the joint fit of 6 columns needs at least 12")


def test_negative_covariates_are_rejected(tmp_path):
    path = _residual_csv(tmp_path / "r.csv", radius_px=np.r_[-1.0, np.full(39, 100.0)])
    _fails(run("triage", path), "radius_px must not be negative; negative at line 2")


def test_camera_filter_errors(logs):
    _fails(
        run("triage", logs / "rotation.csv", "--camera", "cam9"),
        "camera 'cam9' is not in rotation.csv",
        "cameras present: cam0, cam1",
    )


def test_camera_filter_without_camera_column(tmp_path):
    _fails(run("triage", _residual_csv(tmp_path / "r.csv"), "--camera", "cam0"), "has no camera column")


def test_gauge_timestamps_must_increase(tmp_path):
    t = np.arange(0.0, 70.0, 0.5)
    t[20] = t[19]
    d = np.cumsum(np.full(t.size, 0.4))
    write_table(tmp_path / "o.csv", {"t_s": t, "wheel_distance_m": d, "vio_distance_m": d})
    _fails(run("gauge", tmp_path / "o.csv"), "t_s does not increase at line 22")


def test_gauge_log_too_short_and_bad_mode(tmp_path):
    t = np.arange(0.0, 20.0, 0.5)
    d = np.cumsum(np.full(t.size, 0.4))
    write_table(tmp_path / "o.csv", {"t_s": t, "wheel_distance_m": d, "vio_distance_m": d})
    _fails(run("gauge", tmp_path / "o.csv"), "covers 19.5 s; one 60 s window needs at least 60 s")
    _fails(
        run("gauge", tmp_path / "o.csv", "--distances", "odd"),
        "--distances must be auto, cumulative or per-sample",
    )


def test_timeoffset_logs_that_do_not_overlap(logs, tmp_path):
    gyro = (logs / "time-offset_gyro.csv").read_text().splitlines()
    shifted = [gyro[0]] + [
        f"{float(line.split(',')[0]) + 1000:.6f},{line.split(',')[1]}" for line in gyro[1:]
    ]
    (tmp_path / "late.csv").write_text("\n".join(shifted) + "\n")
    _fails(
        run("timeoffset", tmp_path / "late.csv", logs / "time-offset_camera.csv"),
        "the logs do not overlap in time",
    )


def test_timeoffset_too_few_rows_and_unsorted_stamps(tmp_path):
    write_table(tmp_path / "few.csv", {"t_s": np.arange(5.0), "rate_rad_s": np.zeros(5)})
    _fails(
        run("timeoffset", tmp_path / "few.csv", tmp_path / "few.csv"),
        "has 5 data rows; a time-offset estimate needs at least 10",
    )
    write_table(tmp_path / "uns.csv", {"t_s": np.r_[np.arange(10.0), 3.0], "rate_rad_s": np.zeros(11)})
    _fails(run("timeoffset", tmp_path / "uns.csv", tmp_path / "uns.csv"), "t_s does not increase at line 12")


def test_timeoffset_window_too_long_for_a_drift_fit(logs):
    _fails(
        run("timeoffset", logs / "time-offset_gyro.csv", logs / "time-offset_camera.csv", "--window", "8"),
        "which gives 2 window(s) of 8 s; a drift fit needs at least 3",
    )


def test_synth_errors_and_nothing_overwritten(logs):
    before = (logs / "gauge.csv").read_bytes()
    _fails(run("synth-residuals", logs / "gauge.csv", "--fault", "gauge"), "already exist", "--force")
    assert (logs / "gauge.csv").read_bytes() == before
    _fails(
        run("synth-residuals", logs / "x.csv", "--fault", "skew"),
        "unknown fault 'skew'",
        "choose one of focal",
    )
    _fails(run("synth-residuals", logs / "x.csv", "--fault", "gauge", "--magnitude", "0"), "must be positive")


def test_plot_dir_that_is_a_file(logs, tmp_path):
    (tmp_path / "f").write_text("x")
    _fails(
        run("gauge", logs / "gauge_odometry.csv", "--plot", tmp_path / "f"), "exists and is not a directory"
    )


FIXTURES = Path(__file__).resolve().parents[3] / "fixtures" / "diagnostics"


@pytest.mark.parametrize(("stem", "fault"), [("time_offset", "time-offset"), ("gauge", "gauge")])
def test_fixtures_are_reproducible_from_their_readme_command(stem, fault, tmp_path):
    readme = (FIXTURES / "README.md").read_text()
    args = (
        "--fault",
        fault,
        "--seed",
        "1",
        "--keyframes",
        "40",
        "--features",
        "10",
        "--odometry-s",
        "130",
        "--rate-log-s",
        "6",
    )
    assert f"fixtures/diagnostics/{stem}.csv {' '.join(args)} --force" in readme
    assert run("synth-residuals", tmp_path / f"{stem}.csv", *args).exit_code == 0
    for suffix in ("", "_odometry", "_gyro", "_camera"):
        name = f"{stem}{suffix}.csv"
        assert (tmp_path / name).read_bytes() == (FIXTURES / name).read_bytes(), name


def test_fixture_answers_match_the_readme():
    assert run("triage", FIXTURES / "time_offset.csv").exit_code == 1
    assert run("triage", FIXTURES / "gauge.csv").exit_code == 0
    assert run("gauge", FIXTURES / "gauge_odometry.csv").exit_code == 1
    assert run("gauge", FIXTURES / "time_offset_odometry.csv").exit_code == 0
    out = json.loads(
        run(
            "timeoffset", FIXTURES / "time_offset_gyro.csv", FIXTURES / "time_offset_camera.csv", "--json"
        ).stdout
    )
    assert out["td_ms"] == pytest.approx(18.4, abs=0.3)


def test_paths_and_camera_names_with_brackets_are_printed_verbatim(tmp_path):
    d = tmp_path / "run[1]"
    d.mkdir()
    res = run("synth-residuals", d / "b.csv", "--fault", "focal", "--keyframes", "30")
    assert res.exit_code == 0 and "run[1]/b.csv" in res.stdout
    res = run("triage", d / "b.csv")
    assert res.exit_code == 1 and "run[1]/b.csv" in res.stdout
