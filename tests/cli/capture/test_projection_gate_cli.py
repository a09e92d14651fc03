"""The decisive projection gate at capture: station region and threshold, guidance proxies, exit 2 on bad
input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from calibctl.errors import NotFoundError
from calibctl.store.repository import Store
from tests.cli.capture.test_capture_cli import (  # noqa: F401 - the shared store and folder
    SERIAL,
    capture,
    db,
    good,
    invoke,
)
from tests.datasets import DATASETS, needs_datasets

ACFR_IMAGES = DATASETS / "acfr-lidar-camera" / "images"


def _station(tmp_path: Path, gates: str) -> Path:
    station = tmp_path / "station.yaml"
    station.write_text(f"gates: {{{gates}}}\n", encoding="utf-8")
    return station


def test_a_good_session_carries_the_projection_gate_and_says_where_it_judged(db: str, good: Path) -> None:
    r = capture(db, good, "--json")
    assert r.exit_code == 0, r.output
    gate = next(g for g in json.loads(r.stdout)["session"]["gates"] if g["gate"] == "projection")
    assert gate["passed"] and 0 < gate["value"] <= gate["threshold"] == 5.0
    assert gate["detail"]["region"] == "the whole image" and gate["detail"]["model"] == "k1k2"


def test_a_strict_station_threshold_refuses_naming_where(db: str, good: Path, tmp_path: Path) -> None:
    station = _station(tmp_path, "projection_sigma_max_px: 0.05")
    r = capture(db, good, station=station)
    assert r.exit_code == 1, r.output
    assert "gate projection    FAIL" in r.stdout and "(at most 0.05)" in r.stdout
    assert "capture views with the board in the" in r.stdout and "projection.uncertain" in r.stdout


@pytest.mark.parametrize(
    ("gates", "words"),
    [
        ("projection_sigma_max_px: 0", "greater than 0"),
        ("projection_sigma_max_px: .nan", "finite number"),
        ("projection_sigma_max_px: -2", "greater than 0"),
    ],
)
def test_a_threshold_of_zero_or_nan_is_exit_2(
    db: str,
    good: Path,
    tmp_path: Path,
    gates: str,
    words: str,
) -> None:
    r = capture(db, good, station=_station(tmp_path, gates))
    assert r.exit_code == 2, r.output
    assert "projection_sigma_max_px" in r.stderr and words in r.stderr


@pytest.mark.parametrize(
    ("region", "words"),
    [
        ("'0,0,9999,100'", "is not a box inside the 640x480 image"),
        ("circle", "needs an image circle"),
        ("'1,2,x,4'", "is not auto, image, circle or U0,V0,U1,V1"),
    ],
)
def test_a_region_outside_the_image_is_exit_2_and_stores_no_session(
    db: str,
    good: Path,
    tmp_path: Path,
    region: str,
    words: str,
) -> None:
    r = capture(db, good, station=_station(tmp_path, f"projection_region: {region}"))
    assert r.exit_code == 2, r.output
    assert "gates.projection_region" in r.stderr and words in r.stderr
    with Store.open(db) as store:
        assert store.list_sessions(SERIAL) == []


@needs_datasets
@pytest.mark.skipif(not ACFR_IMAGES.is_dir(), reason=f"acfr-lidar-camera not found at {ACFR_IMAGES}")
def test_a_real_fisheye_set_is_refused_for_the_corners_it_never_saw_and_accepted_where_the_robot_looks(
    db: str, tmp_path: Path
) -> None:
    """acfr-lidar-camera: 20 real 1920x1208 views of a 5x7 95 mm board, never in the bottom corners.
    Coverage (6 of 9 cells) refused it before; the projection gate refuses the whole image naming the corners
    (worst sigma 9.4 px), and accepts a station that uses the middle band (a fisheye fit equal to plain
    cv2.fisheye.calibrate, 0.131 px)."""
    added = invoke(
        db,
        "board",
        "add",
        "ACFR",
        "--cols",
        "5",
        "--rows",
        "7",
        "--square-mm",
        "95",
        "--uncertainty-mm",
        "0.5",
        "--instrument",
        "their cfg/params.yaml",
        "--measured-by",
        "acfr",
        "--measured-on",
        "2021-03-01",
    )
    assert added.exit_code == 0, added.output
    args = (
        "calibrate",
        "--serial",
        "ACFR",
        "--board",
        "ACFR",
        "--source",
        str(ACFR_IMAGES),
        "--model",
        "fisheye",
        "--json",
    )
    whole = invoke(db, *args)
    assert whole.exit_code == 1, whole.output
    assert json.loads(whole.stdout)["calibration"] is None  # refused at capture
    gates = {g["gate"]: g for g in json.loads(whole.stdout)["capture"]["session"]["gates"]}
    assert gates["coverage"]["advisory"] and not gates["projection"]["passed"]
    assert any("corner" in c for c in gates["projection"]["detail"]["uncertain_cells"])
    station = _station(tmp_path, "projection_region: '320,200,1600,1000'")
    band = json.loads(invoke(db, "--station-config", str(station), *args).stdout)
    gate = next(g for g in band["capture"]["session"]["gates"] if g["gate"] == "projection")
    assert gate["passed"] and gate["detail"]["model"] == "fisheye"
    assert "the box (320, 200)-(1600, 1000)" in gate["detail"]["region"]
    assert band["calibration"] is not None and band["calibration"]["model"]["name"] == "fisheye"  # solved


def test_the_solve_records_the_station_region_and_lint_judges_fold_over_there(
    db: str,
    good: Path,
    tmp_path: Path,
) -> None:
    assert capture(db, good).exit_code == 0
    station = _station(tmp_path, "projection_region: '100,50,540,430'")
    r = invoke(db, "--station-config", str(station), "solve", "--serial", SERIAL, "--json")
    assert r.exit_code == 0, r.output
    with Store.open(db) as store:
        art = store.list_artifacts(SERIAL)[-1]
    assert art.required_region_px == [(100.0, 50.0), (540.0, 50.0), (540.0, 430.0), (100.0, 430.0)]
    assert art.observed_region_px is not None


def test_the_default_region_records_none(db: str, good: Path) -> None:
    assert capture(db, good).exit_code == 0
    assert invoke(db, "solve", "--serial", SERIAL).exit_code == 0
    with Store.open(db) as store:
        art = store.list_artifacts(SERIAL)[-1]
    assert art.required_region_px is None and "required_region_px" not in art.model_dump(mode="json")


@pytest.mark.parametrize(
    ("region", "words"),
    [
        ("'0,0,9999,100'", "is not a box inside the 640x480 image"),
        ("'0,0,nan,100'", "four finite numbers"),
        ("circle", "needs an image circle"),
    ],
)
def test_a_bad_station_region_at_the_solve_is_exit_2_and_stores_nothing(
    db: str,
    good: Path,
    tmp_path: Path,
    region: str,
    words: str,
) -> None:
    assert capture(db, good).exit_code == 0
    station = _station(tmp_path, f"projection_region: {region}")
    r = invoke(db, "--station-config", str(station), "solve", "--serial", SERIAL)
    assert r.exit_code == 2, r.output
    assert "gates.projection_region" in r.stderr and words in r.stderr
    with Store.open(db) as store, pytest.raises(NotFoundError, match="none was solved"):
        store.list_artifacts(SERIAL)
