"""`calibctl rig add | capture | solve | lint | history | show | rollback | export`: wiring, exit codes,
--json."""

from __future__ import annotations

import errno
import json
import os
import shutil
import stat
import tempfile

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.workflows.rig.test_rig_store_flow import WHO, _truth_artifact
from tests.workflows.rig_folders_data import rendered_rig, rig_sources
from tests.workflows.urdf_check import loadable_urdf

RUNNER = CliRunner()


@pytest.fixture(scope="module")
def rig2(tmp_path_factory):
    return rendered_rig(tmp_path_factory)


@pytest.fixture
def db(tmp_path, rig2):
    url = f"sqlite:///{tmp_path / 'c.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board(square_mm=25.0))
        for name in ("CAM0", "CAM1"):
            store.add_artifact(_truth_artifact(rig2, name), activate=True, **WHO)
    return url


def invoke(db, *args):
    return RUNNER.invoke(app, ["--db", db, *args], terminal_width=110)


def _add_rig(db):
    return invoke(db, "rig", "add", "R1", "--camera", "CAM0", "--camera", "CAM1")


def _capture(db, rig2, *extra, cam1=None, command=("rig", "capture", "R1")):
    """Capture rig R1 from the rendered CAM0 folder and the CAM1 folder (`cam1`, else the rendered one)."""
    return invoke(db, *command, "--board", "A17", *rig_sources(rig2, cam1), *extra)


def test_the_whole_rig_flow_on_the_command_line(db, rig2, tmp_path):
    r = invoke(
        db,
        "rig",
        "add",
        "R1",
        "--camera",
        "CAM0",
        "--camera",
        "CAM1",
        "--design-baseline-mm",
        "CAM0:CAM1=75+-0.5",
    )
    assert r.exit_code == 0 and "design CAM0-CAM1 75.000 +/- 0.500 mm" in r.output
    r = _capture(db, rig2)
    assert r.exit_code == 0, r.output
    assert "8 synchronised frames" in r.output and "gate rig-connected pass" in r.output
    r = invoke(db, "rig", "solve", "R1")
    assert r.exit_code == 0, r.output
    assert "rig R1@1 (active)  accepted" in r.output and "T_CAM0_CAM1: |t| = 75." in r.output
    r = invoke(db, "--json", "rig", "lint", "R1")
    assert r.exit_code == 0 and json.loads(r.output)["verdict"] == "pass"
    assert invoke(db, "rig", "solve", "R1").exit_code == 0
    r = invoke(db, "rig", "rollback", "R1", "--to", "1", "--reason", "compare")
    assert r.exit_code == 0 and "active version 2 -> 1" in r.output
    r = invoke(db, "--json", "rig", "history", "R1")
    doc = json.loads(r.output)
    assert doc["active_version"] == 1 and [v["version"] for v in doc["versions"]] == [1, 2]
    assert json.loads(invoke(db, "--json", "rig", "show", "R1@2").output)["version"] == 2
    r = invoke(db, "rig", "export", "R1", "--format", "opencv", "-o", str(tmp_path / "s.yaml"))
    assert r.exit_code == 0 and (tmp_path / "s.yaml").is_file()
    r = invoke(db, "rig", "export", "R1", "--format", "tf")
    assert r.exit_code == 0 and "child_frame_id: cam1_optical_frame" in r.output
    r = invoke(db, "rig", "export", "R1", "--format", "urdf", "--frame", "CAM0=front/left_optical_frame")
    assert r.exit_code == 0 and loadable_urdf(r.output)[:2] == ("R1", "front/left_optical_frame")
    assert r.output.startswith('<?xml version="1.0"?>\n<!-- calibctl rig R1@1 accepted sha256 ')
    r = invoke(db, "rig", "export", "R1", "--format", "urdf-joints")
    assert r.exit_code == 0 and "<robot" not in r.output
    assert '<joint name="cam0_optical_frame_to_cam1_optical_frame" type="fixed">' in r.output


def test_a_stale_member_fails_rig_lint_with_exit_1(db, rig2):
    _add_rig(db)
    _capture(db, rig2)
    invoke(db, "rig", "solve", "R1")
    with Store.open(db) as store:
        store.add_artifact(_truth_artifact(rig2, "CAM0"), activate=True, **WHO)
    r = invoke(db, "rig", "lint", "R1")
    assert r.exit_code == 1 and "rig-stale-member" in r.output and "CAM0@2" in r.output


def test_refusals_exit_2_with_a_message(db, rig2):
    r = invoke(db, "rig", "add", "R1", "--camera", "CAM0", "--camera", "NOPE")
    assert r.exit_code == 2 and "unknown camera(s) NOPE" in r.output
    r = invoke(db, "rig", "solve", "R9")
    assert r.exit_code == 2 and "unknown rig 'R9'" in r.output
    _add_rig(db)
    r = invoke(db, "rig", "export", "R1", "--format", "nope")
    assert r.exit_code == 2 and "unknown rig export format 'nope'" in r.output
    r = invoke(db, "rig", "export", "R1", "--format", "tf")
    assert r.exit_code == 2 and "rig R1 has no calibration yet" in r.output
    r = _capture(db, rig2, "--min-shared-views", "9")
    assert r.exit_code == 1 and "CAM0-CAM1 shares 8 view(s) (needs 9)" in r.output
    assert "Traceback" not in r.output


def test_solve_and_lint_take_rig(db, rig2):
    _add_rig(db)
    _capture(db, rig2)
    r = invoke(db, "solve", "--rig", "R1")
    assert r.exit_code == 0 and "rig R1@1 (active)  accepted" in r.output
    r = invoke(db, "--json", "lint", "--rig", "R1")
    assert r.exit_code == 0
    assert [x["source"] for x in json.loads(r.output)["results"]] == ["rig R1@1"]
    r = invoke(db, "lint", "--rig", "R1", "--serial", "CAM0")
    assert r.exit_code == 0 and "CAM0@1" in r.output and "rig R1@1 (rig): pass" in r.output


def test_capture_takes_rig_and_still_needs_a_serial_without_it(db, rig2):
    _add_rig(db)
    r = _capture(db, rig2, command=("capture", "--rig", "R1"))
    assert r.exit_code == 0, r.output
    assert "8 synchronised frames" in r.output
    r = invoke(db, "capture", "--board", "A17", "--source", str(rig2 / "CAM0"))
    assert r.exit_code == 2 and "capture needs --serial SERIAL" in r.output
    r = invoke(db, "capture", "--serial", "CAM0", "--board", "A17", "--source", "a", "--source", "b")
    assert r.exit_code == 2 and "one camera takes one --source, got 2" in r.output


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (
            ("--reference-distance", "0.45+-0.001", "--reference-source", "fixture"),
            "--reference-distance, --reference-source apply to one camera",
        ),
        (("--reference-distance", "0.45+-0.001"), "--reference-distance applies to one camera"),
        (("--serial", "CAM0"), "--serial applies to one camera"),
        (("--max-views", "10", "--duration", "5"), "--max-views, --duration apply to one camera"),
    ],
)
def test_capture_rig_refuses_the_options_of_one_camera(db, rig2, args, named):
    """They used to be dropped silently: a rig capture gauged nothing and said nothing."""
    _add_rig(db)
    r = _capture(db, rig2, *args, command=("capture", "--rig", "R1"))
    assert r.exit_code == 2, r.output
    text = " ".join(r.output.split())
    assert f"{named}, not to a rig (--rig)" in text and "capture that camera on its own with --serial" in text
    with Store.open(db) as store:
        assert store.list_sessions() == []


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--serial", "CAM0"], "--serial applies"),
        (["--model", "fisheye"], "--model applies"),
        (["--model", "k1k2", "--drop-outliers"], "--model, --drop-outliers apply"),
    ],
)
def test_solve_rig_refuses_the_options_of_one_camera(db, rig2, args, named):
    """They used to be dropped silently: the rig solve uses the members' active calibrations."""
    _add_rig(db)
    assert _capture(db, rig2).exit_code == 0
    r = invoke(db, "solve", "--rig", "R1", *args)
    assert r.exit_code == 2, r.output
    text = " ".join(r.output.split())
    assert (
        f"{named} to one camera, not to a rig (--rig)" in text and "solve that camera's own session" in text
    )
    assert invoke(db, "rig", "history", "R1").exit_code == 2  # nothing solved, nothing stored


def test_refine_intrinsics_without_rig_is_refused(db):
    r = invoke(db, "solve", "--serial", "CAM0", "--refine-intrinsics")
    assert r.exit_code == 2, r.output
    assert "--refine-intrinsics applies to a rig solve (--rig RIG)" in " ".join(r.output.split())


def test_capture_rig_records_the_station_and_operator_it_is_given(db, rig2):
    _add_rig(db)
    r = _capture(
        db, rig2, "--station", "line-7", "--operator", "ana", command=("--json", "capture", "--rig", "R1")
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(r.output)
    assert (doc["rig_session"]["station"], doc["rig_session"]["operator"]) == ("line-7", "ana")
    assert {(s["station"], s["operator"]) for s in doc["camera_sessions"].values()} == {("line-7", "ana")}


def test_the_opencv_stereo_export_fails_like_every_other_write(db, rig2, tmp_path, monkeypatch):
    """It used to let cv2.FileStorage open the file itself: a folder it could not write was a cv2.error
    traceback."""
    _add_rig(db)
    _capture(db, rig2)
    assert invoke(db, "rig", "solve", "R1").exit_code == 0
    r = invoke(db, "rig", "export", "R1", "--format", "opencv")  # stdout, as the other formats
    assert r.exit_code == 0 and r.output.startswith("%YAML") and "P2: !!opencv-matrix" in r.output
    (tmp_path / "plain").write_text("x")
    r = invoke(db, "rig", "export", "R1", "--format", "opencv", "-o", str(tmp_path / "plain" / "s.yaml"))
    assert r.exit_code == 2 and "plain is a file, not a folder" in r.output
    assert isinstance(r.exception, SystemExit)  # a handled error, not a traceback

    def read_only(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", read_only)  # root ignores chmod: simulate a read-only folder
    r = invoke(db, "rig", "export", "R1", "--format", "opencv", "-o", str(tmp_path / "s.yaml"))
    assert r.exit_code == 2 and f"cannot write {tmp_path / 's.yaml'}: permission denied" in r.output
    assert isinstance(r.exception, SystemExit) and not (tmp_path / "s.yaml").exists()


def test_rig_export_and_rig_report_never_replace_a_fifo_or_a_symlink(db, rig2, tmp_path):
    _add_rig(db)
    _capture(db, rig2)
    assert invoke(db, "rig", "solve", "R1").exit_code == 0
    fifo, link, victim = tmp_path / "s.yaml", tmp_path / "r.html", tmp_path / "victim"
    os.mkfifo(fifo)
    victim.write_text("not ours\n")
    os.symlink(victim, link)
    r = invoke(db, "rig", "export", "R1", "--format", "opencv", "-o", str(fifo), "--force")
    assert r.exit_code == 2 and f"cannot write {fifo}: it is a FIFO" in r.output
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    r = invoke(db, "report", "--rig", "R1", "-o", str(link), "--force")
    assert r.exit_code == 2 and f"cannot write {link}: it is a symbolic link" in r.output, r.output
    assert os.path.islink(link) and victim.read_text() == "not ours\n"


def test_a_rig_capture_whose_frames_contradict_each_other_is_a_verdict_and_stores_nothing(db, rig2, tmp_path):
    """The right camera's frame numbers shifted by three (photos not taken together): exit 1, not 2."""
    right = tmp_path / "CAM1"
    right.mkdir()
    photos = sorted((rig2 / "CAM1").iterdir())
    for i, p in enumerate(photos):
        shutil.copy(p, right / f"CAM1_{(i + 3) % len(photos):04d}.png")
    _add_rig(db)
    r = _capture(db, rig2, cam1=right)
    assert r.exit_code == 0, r.output  # each camera's photos are fine on their own
    r = invoke(db, "rig", "solve", "R1")
    assert r.exit_code == 1, r.output
    text = " ".join(r.output.split())
    assert "the rig's frames contradict each other, so the cameras were not rigid or not synchronised" in text
    assert "CAM0-CAM1: per-frame baseline" in text and "Traceback" not in r.output
    r = invoke(db, "rig", "history", "R1")
    assert r.exit_code == 2 and "rig R1 has no calibration yet" in r.output


def _stored(db) -> tuple[list, int, int]:
    """(capture sessions, rig sessions, rig calibrations of R1) in the store."""
    import sqlalchemy as sa

    with Store.open(db) as store:
        sessions = store.list_sessions()
        with store._engine.connect() as conn:
            rig_sessions = conn.execute(sa.text("SELECT count(*) FROM rig_sessions")).scalar_one()
            solved = conn.execute(sa.text("SELECT count(*) FROM rig_calibrations")).scalar_one()
        return sessions, rig_sessions, solved


def test_the_same_folder_for_two_members_is_refused_and_nothing_is_stored(db, rig2, tmp_path):
    """The operator's typo (the LEFT folder for both cameras), then a copy of it: exit 1 with the numbers."""
    _add_rig(db)
    r = _capture(db, rig2, cam1=rig2 / "CAM0")
    assert r.exit_code == 1, r.output
    text = " ".join(r.output.split())
    assert "the members are not distinct cameras: CAM0 and CAM1 hold 8 identical image(s)" in text, text
    assert "nothing was stored" in text and "Traceback" not in r.output
    copy = tmp_path / "copy"
    shutil.copytree(rig2 / "CAM0", copy)  # renamed files, same bytes
    for p in copy.iterdir():
        p.rename(copy / p.name.replace("CAM0", "CAM1"))
    r = _capture(db, rig2, cam1=copy)
    assert r.exit_code == 1 and "identical image(s)" in r.output
    assert _stored(db) == ([], 0, 0)


def test_a_re_encoded_copy_is_the_same_corners_and_is_refused(db, rig2, tmp_path):
    import cv2

    copy = tmp_path / "copy"
    copy.mkdir()
    for p in sorted((rig2 / "CAM0").iterdir()):  # new bytes (a PNG with another compression), the same pixels
        cv2.imwrite(
            str(copy / p.name.replace("CAM0", "CAM1")), cv2.imread(str(p)), [cv2.IMWRITE_PNG_COMPRESSION, 1]
        )
    _add_rig(db)
    r = _capture(db, rig2, cam1=copy)
    assert r.exit_code == 1, r.output
    assert "see the board at the same pixels" in " ".join(r.output.split())
    assert _stored(db) == ([], 0, 0)


def test_a_rig_capture_that_cannot_run_stores_no_member_session(db, rig2, tmp_path):
    right = tmp_path / "CAM1"
    right.mkdir()
    for i, p in enumerate(sorted((rig2 / "CAM1").iterdir())):
        shutil.copy(p, right / f"CAM1_{i + 100:04d}.png")  # no frame number in common
    _add_rig(db)
    r = _capture(db, rig2, cam1=right)
    assert r.exit_code == 2 and "nothing pairs up" in r.output
    assert _stored(db) == ([], 0, 0)


def test_rig_member_sessions_are_not_picked_by_a_single_camera_solve_unless_named(db, rig2):
    _add_rig(db)
    assert _capture(db, rig2).exit_code == 0
    sessions, rig_sessions, _ = _stored(db)
    assert len(sessions) == 2 and rig_sessions == 1  # stored together
    r = invoke(db, "solve", "--serial", "CAM1")
    assert r.exit_code == 2, r.output
    text = " ".join(r.output.split())
    assert "no accepted capture session for serial 'CAM1'" in text and "rig member" in text
    named = next(s for s in sessions if s.serial == "CAM1")
    r = invoke(db, "solve", named.session_id, "--json")  # named, it is the session solved
    assert r.exit_code in (0, 1), r.output
    art = json.loads(r.stdout)
    assert art["serial"] == "CAM1" and art["provenance"]["session_id"] == named.session_id


def test_a_rig_captures_member_sessions_are_chained_like_any_session(db, rig2):
    """The rig capture stores its members in one transaction; each is numbered and chained in its serial's
    session stream, so `db verify` finds nothing inserted outside calibctl."""
    _add_rig(db)
    assert _capture(db, rig2).exit_code == 0
    r = invoke(db, "--json", "db", "verify")
    assert r.exit_code == 0, r.output
    assert invoke(db, "solve", "--serial", "CAM0").exit_code == 2  # still never picked up unnamed


def test_a_session_stored_before_the_checks_existed_is_refused_at_solve(db, rig2, monkeypatch):
    from calibctl.workflows.rig import rigs

    _add_rig(db)
    with monkeypatch.context() as m:  # an older calibctl stored the typo without a word
        m.setattr(rigs.identity, "refuse", lambda *a, **k: None)
        assert _capture(db, rig2, cam1=rig2 / "CAM0").exit_code == 0
    r = invoke(db, "rig", "solve", "R1")
    assert r.exit_code == 1, r.output
    assert "identical image(s)" in r.output and "nothing was stored" in " ".join(r.output.split())
    assert _stored(db)[2] == 0


def test_a_baseline_indistinguishable_from_zero_is_refused_before_storing(db, rig2, monkeypatch):
    from calibctl.workflows.rig import rigs

    _add_rig(db)
    assert _capture(db, rig2).exit_code == 0
    real = rigs.identity.zero_baselines
    monkeypatch.setattr(
        rigs.identity,
        "zero_baselines",  # this rig's 75 mm read against a 100 mm floor
        lambda pairs: real(pairs, floor_mm=100.0),
    )
    r = invoke(db, "rig", "solve", "R1")
    assert r.exit_code == 1, r.output
    assert "CAM0-CAM1 baseline 75." in r.output and "below the 100 mm floor" in " ".join(r.output.split())
    assert _stored(db)[2] == 0


def test_solve_of_a_session_under_another_serial_is_refused(db, rig2):
    _add_rig(db)
    assert _capture(db, rig2).exit_code == 0
    named = next(s for s in _stored(db)[0] if s.serial == "CAM1")
    r = invoke(db, "solve", named.session_id, "--serial", "CAM0")
    assert r.exit_code == 2 and f"session {named.session_id} is of camera CAM1, not CAM0" in r.output
