"""`calibctl capture --reference-distance`: the gauge at capture catches the 23 mm typo before any solve (seed
chapter 0)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from calibctl.core.intrinsics import model_select
from calibctl.errors import NotFoundError, NumericalError
from calibctl.store.repository import Store
from calibctl.workflows.camera import distance_gauge
from tests.cli.capture.test_check_cli import assets, db, invoke  # noqa: F401 - the shared rendered fixtures
from tests.workflows.synth_folders import FISHEYE_FIXTURE_M, fisheye_gauge_folders

GAUGE = ("--reference-distance", "0.450+-0.0005")


def _run(db: str, command: str, serial: str, board: str, source: Path, *extra: str):
    """`capture` or `calibrate` of one camera's folder against a registered board."""
    return invoke(db, command, "--serial", serial, "--board", board, "--source", str(source), *extra)


def _gauge(fixture: Path, distance: tuple[str, str] = GAUGE) -> tuple[str, ...]:
    """The distance gauge's options: the surveyed distance and the folder of fixture pictures."""
    return (*distance, "--reference-source", str(fixture))


def _capture(db: str, assets, board: str, *extra: str):
    return _run(db, "capture", "CAM-NEW", board, assets["good"], *extra)


def test_a_board_registered_at_23mm_passes_the_gates_and_fails_the_gauge(db: str, assets) -> None:
    done = _capture(db, assets, "TYPO", *_gauge(assets["fixture"]))
    assert done.exit_code == 1, done.output
    assert "ratio 0.920" in done.stdout and "FAIL" in done.stdout
    assert "the metric scale is wrong (board square size?); the residual cannot show it" in done.stdout
    with Store.open(db) as store:
        (session,) = store.list_sessions("CAM-NEW")
    assert session.status == "accepted"  # every gate passed: only the gauge sees it
    # ... and the session carries the failed gauge (it used to be forgotten once stored)
    assert session.metric_gauge is not None and not session.metric_gauge.distance.passed
    assert session.metric_gauge.distance.ratio == pytest.approx(0.92, abs=0.004)
    assert session.metric_gauge.lens_model == "k1k2"


def test_a_session_whose_gauge_failed_solves_only_into_a_rejected_calibration(db: str, assets) -> None:
    """Chapter 0: `solve --serial` of the 23 mm session used to store an accepted, ACTIVE calibration."""
    assert _capture(db, assets, "TYPO", *_gauge(assets["fixture"])).exit_code == 1
    done = invoke(db, "solve", "--serial", "CAM-NEW", "--json")
    assert done.exit_code == 1, done.output
    art = json.loads(done.stdout)
    assert art["status"] == "rejected" and art["metric_gauge"]["distance"]["passed"] is False
    (gauge,) = [f for f in art["lint"] if f["rule"] == "metric-gauge"]
    assert gauge["severity"] == "error" and "0.920x the surveyed 0.4500 m" in gauge["message"]
    assert "--override-gauge REASON" in gauge["fix"]
    with Store.open(db) as store:
        assert store.active_version("CAM-NEW") is None


def test_an_override_with_a_reason_is_recorded_and_lint_keeps_a_warning(db: str, assets) -> None:
    assert _capture(db, assets, "TYPO", *_gauge(assets["fixture"])).exit_code == 1
    reason = "fixture bracket bent; surveyed distance invalid until re-survey"
    done = invoke(db, "solve", "--serial", "CAM-NEW", "--override-gauge", reason, "--json")
    assert done.exit_code == 0, done.output
    art = json.loads(done.stdout)
    assert art["status"] == "accepted" and art["provenance"]["gauge_override"] == reason
    (gauge,) = [f for f in art["lint"] if f["rule"] == "metric-gauge"]
    assert gauge["severity"] == "warning" and gauge["message"].endswith(f"overridden: {reason}")
    linted = invoke(db, "lint", "--serial", "CAM-NEW", "--json")  # the stored verdict is the solve's
    assert linted.exit_code == 0, linted.output
    assert "overridden: " in linted.stdout


@pytest.mark.parametrize("reason", ["", "   "])
def test_an_override_without_a_reason_exits_2_and_stores_nothing(db: str, assets, reason: str) -> None:
    assert _capture(db, assets, "TYPO", *_gauge(assets["fixture"])).exit_code == 1
    done = invoke(db, "solve", "--serial", "CAM-NEW", "--override-gauge", reason)
    assert done.exit_code == 2, done.output
    assert "--override-gauge needs a reason" in done.stderr
    with Store.open(db) as store, pytest.raises(NotFoundError):
        store.list_artifacts("CAM-NEW")


def test_an_override_of_a_gauge_that_passed_or_was_never_taken_exits_2(db: str, assets) -> None:
    assert _capture(db, assets, "A17", *_gauge(assets["fixture"])).exit_code == 0
    done = invoke(db, "solve", "--serial", "CAM-NEW", "--override-gauge", "just because")
    assert done.exit_code == 2 and "passed its metric gauge" in done.stderr
    assert "has no failed one; there is nothing to override" in done.stderr
    plain = _run(db, "calibrate", "CAM-NEW", "A17", assets["good"], "--override-gauge", "just because")
    assert plain.exit_code == 2 and "none is asked for" in plain.stderr


def test_the_right_board_passes_the_gauge_and_says_so_in_json(db: str, assets) -> None:
    done = _capture(db, assets, "A17", *_gauge(assets["fixture"]), "--json")
    assert done.exit_code == 0, done.output
    out = json.loads(done.stdout)
    assert out["passed"] and out["distance"]["passed"]
    assert out["distance"]["ratio"] == pytest.approx(1.0, abs=0.004)


@pytest.mark.parametrize("extra", [GAUGE, ("--reference-source", "fixture")])
def test_the_distance_and_its_pictures_go_together(db: str, assets, extra: tuple[str, ...]) -> None:
    done = _capture(db, assets, "A17", *extra)
    assert done.exit_code == 2
    assert "--reference-distance and --reference-source go together" in done.stderr


def test_fixture_pictures_of_another_size_exit_2_naming_both(db: str, assets) -> None:
    done = _capture(db, assets, "A17", *GAUGE, "--reference-source", str(assets["small"]))
    assert done.exit_code == 2
    assert (
        "are not 640x480, the size this session was calibrated at" in done.stderr
        and "(320x240)" in done.stderr
    )


def test_calibrate_does_not_solve_a_session_whose_gauge_failed(db: str, assets) -> None:
    done = _run(db, "calibrate", "CAM-NEW", "TYPO", assets["good"], *_gauge(assets["fixture"]))
    assert done.exit_code == 1, done.output
    assert "ratio 0.920" in done.stdout and "not solved: the distance gauge failed" in done.stdout
    # no calibration was stored
    with (
        Store.open(db) as store,
        pytest.raises(NotFoundError, match="no calibration is stored for 'CAM-NEW'"),
    ):
        store.list_artifacts("CAM-NEW")


def test_calibrate_with_an_override_solves_and_records_it(db: str, assets) -> None:
    done = _run(
        db,
        "calibrate",
        "CAM-NEW",
        "TYPO",
        assets["good"],
        *_gauge(assets["fixture"]),
        "--override-gauge",
        "gauge under repair",
        "--json",
    )
    assert done.exit_code == 0, done.output
    out = json.loads(done.stdout)
    assert out["calibration"]["provenance"]["gauge_override"] == "gauge under repair"
    assert out["calibration"]["metric_gauge"]["distance"]["ratio"] == pytest.approx(0.92, abs=0.004)


# A fisheye station: the gauge judges through the lens the session is solved with (--model).
FISHEYE_GAUGE = ("--reference-distance", f"{FISHEYE_FIXTURE_M:.3f}+-0.0003")


@pytest.fixture(scope="module")
def fisheye(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return fisheye_gauge_folders(tmp_path_factory)


def _fisheye(db: str, command: str, session: Path, *extra: str):
    return _run(db, command, "FE-0007", "A17", session, *extra)


def test_calibrate_model_fisheye_gauges_a_fisheye_board_through_the_fisheye_lens(db: str, fisheye) -> None:
    session, fixture = fisheye
    done = _fisheye(db, "calibrate", session, "--model", "fisheye", *_gauge(fixture, FISHEYE_GAUGE), "--json")
    assert done.exit_code == 0, done.output
    out = json.loads(done.stdout)
    distance = out["capture"]["distance"]
    assert out["capture"]["passed"] and distance["passed"]
    assert distance["ratio"] == pytest.approx(1.0, abs=0.003)
    assert out["calibration"]["model"]["name"] == "fisheye" and out["active"]


def test_calibrate_model_auto_gauges_through_the_model_auto_chooses(
    db: str, fisheye, monkeypatch: pytest.MonkeyPatch
) -> None:
    """auto used to gauge with k1k2, which fails this correct fisheye board (ratio 1.136): the session was
    never solved. Now the gauge judges through the model the solve then chooses (one ladder for both)."""
    ladders = []
    walk = model_select._select_model
    monkeypatch.setattr(model_select, "_select_model", lambda *a: ladders.append(a) or walk(*a))
    session, fixture = fisheye
    done = _fisheye(db, "calibrate", session, "--model", "auto", *_gauge(fixture, FISHEYE_GAUGE), "--json")
    assert done.exit_code in (0, 1), done.output  # 1: lint's verdict on the chosen model, not the gauge's
    out = json.loads(done.stdout)
    distance = out["capture"]["distance"]
    assert out["capture"]["passed"] and distance["ratio"] == pytest.approx(1.0, abs=0.003)
    assert out["calibration"] is not None  # solved: the gauge did not stop it
    lens = out["capture"]["gauge_lens"]
    assert lens != "k1k2" and lens == out["calibration"]["model"]["name"] and len(ladders) == 1
    capture_only = _fisheye(db, "capture", session, *_gauge(fixture, FISHEYE_GAUGE), "--model", "auto")
    assert capture_only.exit_code == 0, capture_only.output
    assert f"gauged through {lens}, the model --model auto chooses for this session" in capture_only.stdout


def test_capture_model_sets_the_gauge_lens_and_without_it_k1k2_fails_a_fisheye(db: str, fisheye) -> None:
    session, fixture = fisheye
    args = ("capture", session, *_gauge(fixture, FISHEYE_GAUGE))
    plain = _fisheye(db, *args)  # a plain capture gauges with k1k2, the wrong lens for this camera
    assert plain.exit_code == 1, plain.output
    assert "FAIL" in plain.stdout
    done = _fisheye(db, *args, "--model", "fisheye")
    assert done.exit_code == 0, done.output
    assert "vs surveyed 0.1500 m" in done.stdout and " pass" in done.stdout


def test_capture_model_without_a_reference_distance_exits_2(db: str, fisheye) -> None:
    session, _ = fisheye
    done = _fisheye(db, "capture", session, "--model", "fisheye")
    assert done.exit_code == 2
    assert (
        "--model on capture is the lens of the distance gauge; it needs --reference-distance" in done.stderr
    )
    assert "calibctl calibrate" in done.stderr


def test_capture_with_an_unknown_gauge_model_exits_2(db: str, fisheye) -> None:
    session, fixture = fisheye
    done = _fisheye(db, "capture", session, *_gauge(fixture, FISHEYE_GAUGE), "--model", "fish")
    assert done.exit_code == 2
    assert "unknown distortion model 'fish'" in done.stderr and "fisheye" in done.stderr


def test_a_session_the_gauge_model_cannot_solve_exits_2_without_a_traceback_or_a_session(
    db: str, fisheye, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_solution(*_args, **_kwargs):
        raise NumericalError(
            "the solve diverged: fx=3 fy=3 cx=320 cy=240 px", "capture views tilted 20-40 deg"
        )

    monkeypatch.setattr(distance_gauge, "solve_intrinsics", no_solution)
    session, fixture = fisheye
    done = _fisheye(db, "calibrate", session, "--model", "fisheye", *_gauge(fixture, FISHEYE_GAUGE))
    assert done.exit_code == 2, done.output
    assert (
        "the distance gauge cannot judge this session: its 10 views do not solve with the fisheye lens "
        "model (the solve diverged"
    ) in done.stderr
    assert "no session was stored" in done.stderr and "Traceback" not in done.output
    with Store.open(db) as store:
        assert store.list_sessions("FE-0007") == []
