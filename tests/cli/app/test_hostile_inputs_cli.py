"""Readers survive every file and every number (docs/hardening.md): non-UTF-8 and ESC-laden file names,
1x1 and over-size images, nan/inf/1e308 in options and inputs, generators bounded in size."""

from __future__ import annotations

import csv
import os
import shutil
import struct
import zlib

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from calibctl.bounded import printable
from calibctl.cli.main import app
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture.image_outcomes import NO_BOARD, UNREADABLE, classify_file, read_gray
from calibctl.store.repository import Store
from tests.cli.capture.test_capture_cli import capture, db, good, sessions  # noqa: F401 - fixtures

RUNNER = CliRunner()


def invoke(*args: object):
    return RUNNER.invoke(app, [str(a) for a in args], terminal_width=200)


def _png_header(width: int, height: int) -> bytes:
    """A PNG that claims ``width`` x ``height`` (an over-size picture's header, without its pixels)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(b"\x00" * 64))
        + chunk(b"IEND", b"")
    )


def test_printable_escapes_controls_and_bytes_that_are_not_utf8():
    assert printable(os.fsdecode(b"view-\xff\xfe.png")) == "view-\\xff\\xfe.png"
    assert printable("a\x1b[31mred\x07") == "a\\x1b[31mred\\x07"
    assert printable("two\nlines\tand ± µ") == "two\nlines\tand ± µ"


def test_tiny_and_over_size_images_are_outcomes_not_crashes(tmp_path):
    spec = BoardSpec.chessboard(9, 6, 0.025)
    cv2.imwrite(str(tmp_path / "one.png"), np.zeros((1, 1), np.uint8))
    (tmp_path / "huge.png").write_bytes(_png_header(100_000, 100_000))
    tiny = classify_file(tmp_path / "one.png", spec)
    assert tiny.status == NO_BOARD and "only 1x1 px" in tiny.reason
    assert classify_file(tmp_path / "huge.png", spec).status == UNREADABLE
    assert read_gray(tmp_path / "huge.png") is None and read_gray(tmp_path / "missing.png") is None


def test_capture_of_a_file_named_in_latin1_and_with_escapes_is_stored_with_a_printable_name(
    db, good, tmp_path
):
    folder = tmp_path / "views"
    shutil.copytree(good, folder)
    first = sorted(folder.glob("view-*.png"))[0]
    os.rename(bytes(first), bytes(folder) + b"/view-\xff\xfe.png")  # cv2.imread segfaulted on this name
    second = sorted(folder.glob("view-*.png"))[0]
    second.rename(folder / "view-\x1b[2J.png")
    sorted(folder.glob("view-0*.png"))[0].rename(folder / "view-[red]7.png")  # rich markup, not a colour
    cv2.imwrite(str(folder / "tiny.png"), np.zeros((1, 1), np.uint8))
    (folder / "huge.png").write_bytes(_png_header(100_000, 100_000))
    result = capture(db, folder)
    assert result.exit_code in (0, 1), result.output
    assert "Traceback" not in result.output and "\x1b[2J" not in result.output
    assert "view-[red]7.png" in result.output and "view-\\x1b[2J.png" in result.output
    [session] = sessions(db)
    names = {o.name: o.status for o in session.outcomes}
    assert names["view-\\xff\\xfe.png"] == "accepted" and names["view-\\x1b[2J.png"] == "accepted"
    assert names["tiny.png"] == "wrong_size" and names["huge.png"] == "unreadable"  # in a folder of 640x480


def test_a_folder_of_nothing_but_1x1_images_is_exit_2_with_a_message(db, tmp_path):
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"t{i}.png"), np.zeros((1, 1 + i), np.uint8))
    result = capture(db, tmp_path)
    assert result.exit_code == 2 and "no 9x6 chessboard" in result.output and "Traceback" not in result.output
    assert sessions(db) == []


@pytest.mark.parametrize(
    "args",
    [
        ("synth-motions", "{out}", "--amplitude-deg", "inf"),
        ("synth-motions", "{out}", "--time-offset-ms", "nan"),
        ("synth-motions", "{out}", "--translation-m", "1e308", "0", "0"),
        ("synth-residuals", "{out}", "--fault", "focal", "--magnitude", "nan"),
        ("synth-residuals", "{out}", "--fault", "focal", "--drift-ppm", "-inf"),
    ],
)
def test_non_finite_options_are_exit_2_naming_the_option(tmp_path, args):
    out = tmp_path / "out.csv"
    result = invoke(*[a.format(out=out) for a in args])
    assert result.exit_code == 2, result.output
    flag = next(a for a in args if a.startswith("--") and a != "--fault")
    assert f"{flag} " in result.stderr and "is not a usable number" in result.stderr
    assert list(tmp_path.iterdir()) == []  # nothing written


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (
            ("synth-residuals", "{out}", "--fault", "focal", "--keyframes", "10000000"),
            "800000000 is over the limit of 5000000 rows per file",
        ),
        (
            ("synth-residuals", "{out}", "--fault", "focal", "--odometry-s", "1e9"),
            "over the limit of 5000000 rows",
        ),
        (("synth-motions", "{out}", "--rows", str(10**9)), "--rows 1000000000 is out of range (2 .. 100000)"),
    ],
)
def test_generators_are_bounded_before_they_allocate(tmp_path, args, words):
    out = tmp_path / "out.csv"
    result = invoke(*[a.format(out=out) for a in args])
    assert result.exit_code == 2 and words in result.stderr, result.output
    assert list(tmp_path.iterdir()) == []


def test_a_hand_eye_translation_of_1e308_is_exit_2_naming_the_line(tmp_path):
    log = tmp_path / "m.csv"
    assert invoke("synth-motions", log, "--seed", "1").exit_code == 0
    rows = list(csv.reader(log.open()))
    rows[3][rows[0].index("a_tx_m")] = "1e308"
    with log.open("w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    result = invoke("handeye", log, "--from", "lidar", "--to", "camera")
    assert result.exit_code == 2, result.output
    assert "a translation over 1e+08 m at line 4 (up to 1e+308 m)" in result.stderr


def test_synth_baseline_without_rig_is_refused(tmp_path):
    result = invoke("synth", tmp_path / "o", "--baseline-mm", "75")
    assert (
        result.exit_code == 2
        and "--baseline-mm places the cameras of a rig; it needs --rig N" in result.stderr
    )
    assert not (tmp_path / "o").exists()


def test_an_error_message_never_carries_a_raw_escape(sqlite_url, tmp_path):
    with Store.open(sqlite_url):
        pass
    result = invoke("--db", sqlite_url, "show", "CAM\x1b[2J")
    assert result.exit_code == 2 and "\x1b" not in result.stderr and "\\x1b[2J" in result.stderr, (
        result.stderr
    )


@pytest.mark.parametrize("value", ["-1", "0"])
def test_a_rig_gate_that_links_nothing_is_refused(tmp_path, value):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    result = invoke(
        "rig",
        "solve-folders",
        "--source",
        f"A={tmp_path / 'a'}",
        "--source",
        f"B={tmp_path / 'b'}",
        "--cols",
        "9",
        "--rows",
        "6",
        "--square-mm",
        "25",
        "--min-shared-views",
        value,
    )
    assert (
        result.exit_code == 2 and f"--min-shared-views {value} is out of range (1 .. 10000)" in result.stderr
    )


def test_a_rollback_reason_of_100000_characters_is_refused_before_the_store_opens(sqlite_url):
    result = invoke("--db", sqlite_url, "rollback", "CAM-0001", "--to", "1", "--reason", "x" * 100_000)
    assert result.exit_code == 2 and "the reason is 100000 characters long (at most 2000)" in result.stderr


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("gates:\n  min_views: 1000000000000000000000\n", "min_views"),
        ("lint:\n  sigma_fx_max_px: .inf\n", "sigma_fx_max_px"),
    ],
)
def test_a_station_file_with_absurd_numbers_is_refused(sqlite_url, tmp_path, text, words):
    station = tmp_path / "station.yaml"
    station.write_text(text)
    result = invoke("--db", sqlite_url, "--station-config", station, "history", "CAM-0001")
    assert result.exit_code == 2 and words in result.stderr and "Traceback" not in result.output, (
        result.output
    )


def test_db_verify_names_and_prune_removes_the_files_a_failed_capture_left(sqlite_url, tmp_path):
    import hashlib

    from calibctl.store.images import ORPHAN_GRACE_S, image_file

    with Store.open(sqlite_url) as store:
        kept = store.put_image(b"kept image", retention_days=30)
        image_dir = store.image_dir
    data = b"written before the disk filled up"
    orphan = image_file(image_dir, hashlib.sha256(data).hexdigest())
    orphan.parent.mkdir(parents=True, exist_ok=True)
    orphan.write_bytes(data)
    old = orphan.stat().st_mtime - ORPHAN_GRACE_S - 60
    os.utime(orphan, (old, old))
    verified = invoke("--db", sqlite_url, "db", "verify")
    assert verified.exit_code == 0 and "images: 1 file(s) no record refers to" in verified.stdout, (
        verified.output
    )
    pruned = invoke("--db", sqlite_url, "prune")
    assert pruned.exit_code == 0 and "pruned 1 " in pruned.stdout, pruned.output
    assert not orphan.exists() and image_file(image_dir, kept).exists()
    assert "no record refers to" not in invoke("--db", sqlite_url, "db", "verify").stdout
