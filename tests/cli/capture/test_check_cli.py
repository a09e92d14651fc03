"""`calibctl check`: re-test on rendered and real photos, the station distance gauge, every bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from sqlalchemy import exc as sa_exc
from sqlalchemy import text
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.synth.pinhole import PinholeCamera, render_view
from calibctl.core.synth.scenes import place_board, tilt_rotation
from calibctl.store.engine import make_engine
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import rendered

RUNNER = CliRunner()
FIXTURE_DISTANCE_M = 0.45  # the surveyed camera-to-board-centre distance of the rendered fixture views
BOARD = BoardSpec.chessboard(9, 6, 0.025)  # what is printed: 25 mm squares


def invoke(db: str, *args: str):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=110)


def _render_fixture(out: Path, size: tuple[int, int], n: int = 10) -> Path:
    """Board held at FIXTURE_DISTANCE_M on the optical axis, tilted 25 deg toward n directions."""
    camera = PinholeCamera.seed_reference(size)
    out.mkdir(parents=True)
    rng = np.random.default_rng(5)
    centre = (float(camera.K[0, 2]), float(camera.K[1, 2]))
    for i in range(n):
        R = tilt_rotation(np.deg2rad(25.0), 2 * np.pi * i / n, 0.1 * i)
        T = place_board(camera, BOARD, R, centre, FIXTURE_DISTANCE_M)
        cv2.imwrite(str(out / f"fixture{i:02d}.png"), render_view(camera, BOARD, T, rng))
    return out


@pytest.fixture(scope="module")
def assets(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path | str]:
    """One store: CAM-GOOD calibrated with the 25 mm board as 25 mm, CAM-TYPO with it registered as 23 mm."""
    root = tmp_path_factory.mktemp("check")
    url = f"sqlite:///{root / 'calibctl.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
        store.add_board(measured_board("TYPO", square_mm=23.0))
    good = rendered(tmp_path_factory, "good")
    for serial, board in (("CAM-GOOD", "A17"), ("CAM-TYPO", "TYPO")):
        done = invoke(url, "calibrate", "--serial", serial, "--board", board, "--source", str(good))
        assert done.exit_code == 0, done.output
    return {
        "db": root / "calibctl.db",
        "good": good,
        "fixture": _render_fixture(root / "fixture", (640, 480)),
        "small": _render_fixture(root / "small", (320, 240), n=2),
    }


@pytest.fixture
def db(assets, tmp_path: Path) -> str:
    shutil.copy(assets["db"], tmp_path / "calibctl.db")
    return f"sqlite:///{tmp_path / 'calibctl.db'}"


def test_an_unchanged_camera_passes_and_the_check_is_in_its_history(db: str, assets) -> None:
    done = invoke(db, "check", "CAM-GOOD", "--source", str(assets["fixture"]), "--json")
    assert done.exit_code == 0, done.output
    event = json.loads(done.stdout)
    assert event["passed"] and event["version"] == 1 and len(event["views"]) == 10
    assert event["regions"][0]["region"] == "overall" and event["regions"][0]["tested"]
    hist = invoke(db, "history", "CAM-GOOD", "--json")
    assert [c["check_id"] for c in json.loads(hist.stdout)["checks"]] == [event["check_id"]]
    text_hist = invoke(db, "history", "CAM-GOOD")
    assert "checks:" in text_hist.stdout and "check    v1  pass  10 views" in text_hist.stdout


def test_the_23mm_typo_passes_the_residuals_and_is_caught_by_the_reference_distance(db: str, assets) -> None:
    plain = invoke(db, "check", "CAM-TYPO", "--source", str(assets["fixture"]))
    assert plain.exit_code == 0, plain.output  # the seed's point: no residual can see a gauge error
    done = invoke(
        db, "check", "CAM-TYPO", "--source", str(assets["fixture"]), "--reference-distance", "0.450+-0.0005"
    )
    assert done.exit_code == 1, done.output
    assert "ratio 0.920" in done.stdout
    assert "the metric scale is wrong (board square size?); the residual cannot show it" in done.stdout
    good = invoke(
        db, "check", "CAM-GOOD", "--source", str(assets["fixture"]), "--reference-distance", "450+-0.5mm"
    )
    assert good.exit_code == 0, good.output
    assert "distance  0.45" in good.stdout and "ratio 1.00" in good.stdout


def test_a_stored_failed_check_records_its_reason(db: str, assets) -> None:
    invoke(db, "check", "CAM-TYPO", "--source", str(assets["fixture"]), "--reference-distance", "0.45+-0.001")
    with Store.open(db) as store:
        (event,) = store.checks("CAM-TYPO")
    assert (
        not event.passed
        and event.distance is not None
        and event.distance.ratio == pytest.approx(0.92, abs=0.004)
    )
    assert "metric scale is wrong" in event.reasons[0]


def test_images_of_another_size_exit_2_naming_both_sizes(db: str, assets) -> None:
    done = invoke(db, "check", "CAM-GOOD", "--source", str(assets["small"]))
    assert done.exit_code == 2
    assert "are not 640x480, the size CAM-GOOD@1 was calibrated at" in done.stderr
    assert "(320x240)" in done.stderr and "never rescales" in done.stderr
    with Store.open(db) as store:
        assert store.checks("CAM-GOOD") == []


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("450+-0.5", "off by a factor of 1000 (mm for m?)"),
        ("4.5+-0.001", "off by a factor of 10"),
        ("1.2+-0.001", "nowhere near the surveyed 1.200 m"),
    ],
)
def test_a_reference_distance_the_board_never_matches_exits_2(
    db: str, assets, value: str, message: str
) -> None:
    done = invoke(db, "check", "CAM-GOOD", "--source", str(assets["fixture"]), "--reference-distance", value)
    assert done.exit_code == 2, done.output
    assert message in done.stderr and "Hint:" in done.stderr


def test_views_at_several_distances_cannot_match_one_reference(db: str, assets) -> None:
    done = invoke(
        db, "check", "CAM-GOOD", "--source", str(assets["good"]), "--reference-distance", "0.45+-0.001"
    )
    assert done.exit_code == 2
    assert "the board was not held at one distance" in done.stderr


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("far", "is not D+-S"),
        ("0.45+-0.01", "cannot judge a 1 % scale error"),
    ],
)
def test_an_unusable_reference_distance_is_a_usage_error(db: str, assets, value: str, message: str) -> None:
    done = invoke(db, "check", "CAM-GOOD", "--source", str(assets["fixture"]), "--reference-distance", value)
    assert done.exit_code == 2 and message in done.stderr


def test_unknown_serial_and_version_exit_2(db: str, assets) -> None:
    unknown = invoke(db, "check", "CAM-NONE", "--source", str(assets["fixture"]))
    assert unknown.exit_code == 2 and "unknown serial 'CAM-NONE'" in unknown.stderr
    missing = invoke(db, "check", "CAM-GOOD@7", "--source", str(assets["fixture"]))
    assert missing.exit_code == 2 and "Error:" in missing.stderr


def test_check_events_are_immutable_in_the_database(db: str, assets) -> None:
    assert invoke(db, "check", "CAM-GOOD", "--source", str(assets["fixture"])).exit_code == 0
    engine = make_engine(db)
    try:
        for statement in ("UPDATE check_events SET passed = 0", "DELETE FROM check_events"):
            with (
                pytest.raises(sa_exc.DBAPIError, match="check events are append-only"),
                engine.begin() as conn,
            ):
                conn.execute(text(statement))
    finally:
        engine.dispose()


def test_images_without_the_board_exit_2_and_store_nothing(db: str, tmp_path: Path) -> None:
    blank = tmp_path / "blank"
    blank.mkdir()
    cv2.imwrite(str(blank / "wall.png"), np.full((480, 640), 128, np.uint8))
    done = invoke(db, "check", "CAM-GOOD", "--source", str(blank))
    assert done.exit_code == 2
    assert "no board A17@1 was found in the 1 image(s)" in done.stderr
    with Store.open(db) as store:
        assert store.checks("CAM-GOOD") == []


def test_a_video_source_is_refused(db: str, tmp_path: Path) -> None:
    video = tmp_path / "line.mp4"
    video.write_bytes(b"not really a video")
    done = invoke(db, "check", "CAM-GOOD", "--source", str(video))
    assert done.exit_code == 2 and "check reads a folder, glob or list of images, not a video" in done.stderr


@pytest.mark.parametrize("n", [1, 3, 9])
def test_below_the_views_its_statistics_need_check_cannot_judge_and_stores_nothing(
    db: str, assets, tmp_path, n
) -> None:
    few = tmp_path / "few"
    few.mkdir()
    for path in sorted(Path(assets["fixture"]).glob("*.png"))[:n]:
        shutil.copy(path, few / path.name)
    done = invoke(db, "check", "CAM-GOOD", "--source", str(few))
    assert done.exit_code == 2, done.output
    assert (
        f"cannot judge CAM-GOOD@1 from {n} board view(s) in {n} image(s): the check's statistics need at "
        "least 10; nothing was stored"
    ) in done.stderr
    assert f"take {10 - n} more pictures" in done.stderr
    with Store.open(db) as store:
        assert store.checks("CAM-GOOD") == []  # no FAIL written into the camera's history
