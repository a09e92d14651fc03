"""CSV validation with line numbers, atomic writes, and the run_* workflows' documented dicts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calibctl.errors import AlreadyExistsError, FileSystemError, InputError, NotFoundError, UsageError
from calibctl.workflows.diagnostics import diagnostics as wf
from calibctl.workflows.diagnostics.diagnostics_io import read_table, require_increasing, write_table

REQ = ("a", "b")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _write(tmp_path: Path, text: str, name: str = "t.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_fast_and_careful_paths_agree(tmp_path):
    fast = read_table(_write(tmp_path, "a,b,cam\n1,2.5,x\n3,4e-3,y\n"), REQ, optional_text=("cam",))
    careful = read_table(
        _write(tmp_path, 'a,b,cam\n1,2.5,x\n\n3,"4e-3",y\n', "q.csv"), REQ, optional_text=("cam",)
    )
    assert fast.numeric["b"].tolist() == careful.numeric["b"].tolist() == [2.5, 0.004]
    assert fast.text["cam"].tolist() == careful.text["cam"].tolist() == ["x", "y"]
    assert fast.lines.tolist() == [2, 3]
    assert careful.lines.tolist() == [2, 4]  # the blank line 3 keeps the numbering honest


def test_missing_columns_are_named(tmp_path):
    with pytest.raises(InputError, match=r"t.csv is missing column\(s\) b \(found: a, c\)"):
        read_table(_write(tmp_path, "a,c\n1,2\n"), REQ)


def test_non_numeric_cells_are_reported_by_line(tmp_path):
    with pytest.raises(InputError, match=r"column b has non-numeric cells: line 3 \('abc'\), line 5 \(''\)"):
        read_table(_write(tmp_path, "a,b\n1,2\n1,abc\n1,3\n1,\n"), REQ)


def test_many_non_numeric_cells_name_the_first_and_count_the_rest(tmp_path):
    rows = "".join(f"1,x{i}\n" for i in range(8))  # lines 2..9, every one bad
    with pytest.raises(InputError) as bad:
        read_table(_write(tmp_path, "a,b\n" + rows), REQ)
    assert (
        "column b has non-numeric cells: line 2 ('x0'), line 3 ('x1'), line 4 ('x2'), line 5 ('x3'), "
        "line 6 ('x4') and 3 more" in bad.value.message
    )
    assert bad.value.exit_code == 2


def test_non_finite_cells_are_reported_by_line(tmp_path):
    with pytest.raises(InputError, match=r"column a has non-finite values \(nan/inf\) at lines 2, 4"):
        read_table(_write(tmp_path, "a,b\nnan,2\n1,3\ninf,4\n"), REQ)


def test_short_rows_duplicates_empty_and_headers_only(tmp_path):
    with pytest.raises(InputError, match="line 3 has 1 cells, the header has 2"):
        read_table(_write(tmp_path, "a,b\n1,2\n3\n"), REQ)
    with pytest.raises(InputError, match=r"column\(s\) a appear more than once"):
        read_table(_write(tmp_path, "a,a,b\n1,2,3\n"), REQ)
    with pytest.raises(InputError, match="is empty"):
        read_table(_write(tmp_path, ""), REQ)
    with pytest.raises(InputError, match="has a header but no data rows"):
        read_table(_write(tmp_path, "a,b\n"), REQ)
    with pytest.raises(InputError, match="does not exist"):
        read_table(tmp_path / "nope.csv", REQ)


def test_byte_order_mark_and_crlf_are_accepted(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes("\ufeffa,b\r\n1,2\r\n".encode())
    assert read_table(path, REQ).numeric["a"].tolist() == [1.0]


def test_timestamps_must_increase(tmp_path):
    table = read_table(_write(tmp_path, "a,b\n0,0\n1,0\n1,0\n0.5,0\n"), REQ)
    with pytest.raises(InputError, match=r"a does not increase at line 4 \(1 after 1\); 2 such step"):
        require_increasing(table, "a")


def test_write_table_is_atomic_and_never_overwrites_silently(tmp_path):
    path = tmp_path / "out.csv"
    write_table(path, {"x": np.array([1, 2]), "y": np.array([0.5, 1e-9]), "c": np.array(["a", "b"])})
    assert path.read_text() == "x,y,c\n1,0.5,a\n2,1e-09,b\n"
    with pytest.raises(AlreadyExistsError, match="already exists"):
        write_table(path, {"x": np.array([3])})
    write_table(path, {"x": np.array([3])}, force=True)
    assert path.read_text() == "x\n3\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]  # no temporary left behind
    with pytest.raises(FileSystemError, match="does not exist"):
        write_table(tmp_path / "missing" / "o.csv", {"x": np.array([1])})


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("synth")
    wf.run_synth(d / "tdo.csv", "time-offset", seed=3, cameras=2, keyframes=200)
    wf.run_synth(d / "gauge.csv", "gauge", seed=3, keyframes=200)
    return d


def test_synth_writes_four_matching_files(synth_dir):
    files = sorted(p.name for p in synth_dir.glob("tdo*.csv"))
    assert files == ["tdo.csv", "tdo_camera.csv", "tdo_gyro.csv", "tdo_odometry.csv"]
    with pytest.raises(AlreadyExistsError, match="already exist"):
        wf.run_synth(synth_dir / "tdo.csv", "time-offset")
    with pytest.raises(UsageError, match="unknown fault 'skew'"):
        wf.run_synth(synth_dir / "x.csv", "skew")


def test_run_triage_returns_the_documented_dict_and_plots(synth_dir, tmp_path):
    out = wf.run_triage(synth_dir / "tdo.csv", plot_dir=tmp_path / "plots")
    json.dumps(out, allow_nan=False)
    assert out["schema"] == "calibctl.diagnostics.triage/1" and out["verdict"] == "fail"
    cam0 = out["cameras"][0]
    assert cam0["faults"] == ["time_offset"] and cam0["aggregation"] == "keyframe means"
    td = next(c for c in cam0["channels"] if c["key"] == "time_offset")
    assert td["value"] == pytest.approx(0.0184, rel=0.05) and td["value_unit"] == "s"
    assert set(td) >= {"coef", "se", "t", "p_value", "ci95", "value_ci95", "effect_px", "status", "note"}
    assert out["camera_rms"]["level"] == "alarm"
    assert len(out["plots"]) == 2
    assert all(Path(p).read_bytes()[:8] == PNG_MAGIC for p in out["plots"])


def test_run_triage_camera_filter(synth_dir):
    out = wf.run_triage(synth_dir / "tdo.csv", camera="cam1", focal_px=1000.0)
    assert [c["camera"] for c in out["cameras"]] == ["cam1"] and out["verdict"] == "pass"
    assert out["focal_px"] == 1000.0 and out["focal_px_source"] == "option"
    with pytest.raises(NotFoundError, match="camera 'cam7' is not in tdo.csv"):
        wf.run_triage(synth_dir / "tdo.csv", camera="cam7")


def test_run_gauge_auto_detects_cumulative_and_alarms(synth_dir, tmp_path):
    out = wf.run_gauge(synth_dir / "gauge_odometry.csv", plot_dir=tmp_path)
    json.dumps(out, allow_nan=False)
    assert out["schema"] == "calibctl.diagnostics.gauge/1"
    assert out["distances"].startswith("cumulative (auto-detected")
    assert out["verdict"] == "fail" and out["first_alarm_s"] == 0.0
    assert out["median_ratio"] == pytest.approx(25.0 / 23.0, rel=1e-3)
    assert Path(out["plots"][0]).read_bytes()[:8] == PNG_MAGIC


def test_run_gauge_rejects_decreasing_cumulative_and_negative_steps(tmp_path):
    t = np.arange(0.0, 70.0, 0.5)
    d = np.cumsum(np.full(t.size, 0.4))
    d[10] = 0.1
    path = tmp_path / "o.csv"
    write_table(path, {"t_s": t, "wheel_distance_m": d, "vio_distance_m": d})
    with pytest.raises(InputError, match="cumulative wheel_distance_m decreases at line 12"):
        wf.run_gauge(path, distances="cumulative")
    write_table(path, {"t_s": t, "wheel_distance_m": d - 1.0, "vio_distance_m": d}, force=True)
    with pytest.raises(InputError, match="wheel_distance_m must not be negative; negative at line"):
        wf.run_gauge(path)
    with pytest.raises(UsageError, match="--distances must be"):
        wf.run_gauge(path, distances="sometimes")


def test_run_timeoffset_dict_and_drift(synth_dir, tmp_path):
    out = wf.run_timeoffset(
        synth_dir / "tdo_gyro.csv", synth_dir / "tdo_camera.csv", window_s=5.0, plot_dir=tmp_path
    )
    json.dumps(out, allow_nan=False)
    assert out["schema"] == "calibctl.diagnostics.timeoffset/1" and out["verdict"] == "pass"
    assert out["td_ms"] == pytest.approx(18.4, abs=0.3)
    assert out["sign_convention"].startswith("t_gyro = t_camera + td")
    assert out["drift"]["ci95_ppm"][0] < 0 < out["drift"]["ci95_ppm"][1]
    assert len(out["drift"]["windows"]) == 3  # overlap 0..19.967 s holds three full 5 s windows
    assert sorted(Path(p).name for p in out["plots"]) == ["timeoffset.png", "timeoffset_drift.png"]


def test_plot_dir_that_is_a_file_is_refused(synth_dir, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(InputError, match="exists and is not a directory"):
        wf.run_gauge(synth_dir / "gauge_odometry.csv", plot_dir=blocker)


def test_label_columns_are_numeric_when_they_can_be(tmp_path):
    numeric = read_table(_write(tmp_path, "a,b,kf\n1,2,7\n3,4,8\n"), REQ, optional_labels=("kf",))
    assert numeric.labels["kf"].dtype == np.float64 and numeric.labels["kf"].tolist() == [7.0, 8.0]
    for text in ("a,b,kf\n1,2,kf_7\n3,4,kf_8\n", 'a,b,kf\n1,2,"kf_7"\n3,4,kf_8\n'):  # fast and careful paths
        named = read_table(_write(tmp_path, text, "n.csv"), REQ, optional_labels=("kf",))
        assert named.labels["kf"].tolist() == ["kf_7", "kf_8"]
    with pytest.raises(InputError, match=r"column b has non-numeric cells: line 3 \('x'\)"):
        read_table(_write(tmp_path, "a,b,kf\n1,2,kf_7\n3,x,kf_8\n", "bad.csv"), REQ, optional_labels=("kf",))


def test_run_gauge_reads_per_sample_distances(tmp_path):
    from calibctl.core.diagnostics.faults import synth_odometry

    odo = synth_odometry(gauge_scale=1.0, slip_std=0.01, duration_s=130.0, seed=3)
    write_table(tmp_path / "steps.csv", odo)
    out = wf.run_gauge(tmp_path / "steps.csv")
    assert out["distances"].startswith("per-sample (auto-detected")
    assert out["verdict"] == "pass" and len(out["windows"]) == 2
    assert out["median_ratio"] == pytest.approx(1.0, abs=0.002)
