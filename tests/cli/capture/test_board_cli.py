"""calibctl board add | list | show: wiring, messages, exit codes and --json."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.artifacts.common import sha256_hex
from calibctl.cli.main import app

MEASURED = [
    "--uncertainty-mm",
    "0.02",
    "--instrument",
    "Mitutoyo 500-196",
    "--measured-by",
    "qa-anna",
    "--measured-on",
    "2026-03-11",
]
CHESS = ["--cols", "9", "--rows", "6", "--square-mm", "25.03"]


@pytest.fixture
def run(sqlite_url: str, monkeypatch):
    monkeypatch.setenv("CALIBCTL_OPERATOR", "tester")
    runner = CliRunner()

    def invoke(*args: str):
        return runner.invoke(app, ["--db", sqlite_url, *args])

    return invoke


def test_measured_board_is_registered_with_its_provenance(run, tmp_path: Path):
    evidence = tmp_path / "calipers.jpg"
    evidence.write_bytes(b"\xff\xd8\xff photo of the calipers on square 5")
    result = run("board", "add", "A17", *CHESS, *MEASURED, "--evidence", str(evidence), "--json")
    assert result.exit_code == 0, result.output
    board = json.loads(result.stdout)
    assert (board["name"], board["revision"], board["kind"], board["cols"], board["rows"]) == (
        "A17",
        1,
        "chessboard",
        9,
        6,
    )
    m = board["measurement"]
    assert m["status"] == "measured-single" and m["square_size_m"] == 0.02503 and m["uncertainty_m"] == 2e-05
    assert (m["instrument"], m["measured_by"], m["measured_on"]) == (
        "Mitutoyo 500-196",
        "qa-anna",
        "2026-03-11",
    )
    assert m["evidence_sha256"] == sha256_hex(evidence.read_bytes()) and m["evidence_name"] == "calipers.jpg"
    assert board["created_by"] == "tester"
    assert "NOMINAL" not in result.stderr

    shown = run("board", "show", "A17")
    assert shown.exit_code == 0
    assert "board A17@1: chessboard 9x6 inner corners" in shown.stdout
    assert "25.030 mm ± 0.020 mm (1σ)" in shown.stdout
    assert "with Mitutoyo 500-196 by qa-anna on 2026-03-11" in shown.stdout
    assert f"calipers.jpg sha256 {m['evidence_sha256']}" in shown.stdout


def test_board_without_a_measurement_is_nominal_and_warned_about(run):
    result = run("board", "add", "N1", *CHESS)
    assert result.exit_code == 0, result.output
    assert "registered board N1@1: chessboard 9x6 inner corners, square 25.030 mm NOMINAL" in result.stdout
    assert (
        "warning: N1@1 has a NOMINAL square size; every calibration made with it fails lint" in result.stderr
    )
    shown = json.loads(run("board", "show", "N1", "--json").stdout)
    assert shown["measurement"] == {
        "status": "nominal", "square_size_m": 0.02503, "uncertainty_m": None, "instrument": None,
        "measured_by": None, "measured_on": None, "evidence_sha256": None, "evidence_name": None,
    }  # fmt: skip


def test_re_measuring_creates_revision_2_and_name_at_rev_selects(run):
    assert run("board", "add", "A17", *CHESS).exit_code == 0
    second = run(
        "board",
        "add",
        "A17",
        "--cols",
        "9",
        "--rows",
        "6",
        "--square-mm",
        "25.01",
        *MEASURED,
        "--note",
        "re-measured",
    )
    assert second.exit_code == 0 and "registered board A17@2" in second.stdout
    assert "NOMINAL" in run("board", "show", "A17@1").stdout
    latest = run("board", "show", "A17")
    assert "board A17@2" in latest.stdout and "25.010 mm ± 0.020 mm" in latest.stdout
    assert "revisions     1, 2" in latest.stdout and "note          re-measured" in latest.stdout
    listed = run("board", "list", "--json")
    assert [(b["name"], b["revision"]) for b in json.loads(listed.stdout)] == [("A17", 1), ("A17", 2)]
    table = run("board", "list")
    assert "A17@1" in table.stdout and "A17@2" in table.stdout and "2026-03-11 by qa-anna" in table.stdout


def test_charuco_board_records_marker_and_dictionary(run):
    result = run("board", "add", "C1", "--kind", "charuco", "--cols", "10", "--rows", "7",
                 "--square-mm", "30", "--marker-mm", "22.5", "--dictionary", "DICT_5X5_100",
                 "--json")  # fmt: skip
    assert result.exit_code == 0, result.output
    board = json.loads(result.stdout)
    assert (board["kind"], board["marker_size_m"], board["dictionary"]) == ("charuco", 0.0225, "DICT_5X5_100")
    assert "markers 22.500 mm DICT_5X5_100" in run("board", "show", "C1").stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            [*CHESS, "--instrument", "calipers"],
            "a measured square size needs --uncertainty-mm, --instrument, --measured-by, --measured-on; "
            "missing: --uncertainty-mm, --measured-by, --measured-on",
        ),
        (
            [*CHESS, *MEASURED[:6], "--measured-on", "11/03/2026"],
            "--measured-on '11/03/2026' is not a date; use YYYY-MM-DD",
        ),
        (
            [*CHESS, *MEASURED[:6], "--measured-on", "2026-02-30"],
            "--measured-on '2026-02-30' is not a date: day is out of range for month",
        ),
        (
            [*CHESS, *MEASURED[:6], "--measured-on", (dt.date.today() + dt.timedelta(days=30)).isoformat()],
            "is in the future",
        ),
        (
            [*CHESS, "--evidence", "/no/such/photo.jpg", *MEASURED],
            "cannot read evidence file /no/such/photo.jpg: No such file or directory",
        ),
        (
            ["--cols", "9", "--rows", "6", "--square-mm", "0"],
            "--square-mm 0 must be a positive length below 1000 mm",
        ),
        (
            [*CHESS, "--uncertainty-mm", "30", *MEASURED[2:]],
            "--uncertainty-mm 30 must be positive and smaller than the square",
        ),
        ([*CHESS, "--marker-mm", "20"], "--marker-mm and --dictionary apply to ChArUco boards only"),
        (["--kind", "charuco", *CHESS], "a ChArUco board needs --marker-mm and --dictionary"),
        (
            ["--kind", "charuco", *CHESS, "--marker-mm", "20", "--dictionary", "DICT_NOPE"],
            "unknown ArUco dictionary 'DICT_NOPE'",
        ),
        (
            ["--kind", "charuco", *CHESS, "--marker-mm", "26", "--dictionary", "DICT_5X5_100"],
            "0 < marker_size_m < square_size_m",
        ),
        (["--cols", "1", "--rows", "6", "--square-mm", "25"], "at least 2x2 inner corners"),
    ],
)
def test_bad_board_input_exits_2_with_a_message(run, args, message):
    result = run("board", "add", "A17", *args)
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    listed = run("board", "list", "--json")  # nothing was registered: not even a store was created
    assert listed.exit_code == 2 and "there is no calibctl database" in listed.stderr


def test_bad_board_names_are_refused(run):
    result = run("board", "add", "my board", *CHESS)
    assert result.exit_code == 2 and "'my board' is not a board name" in result.stderr


def test_unknown_board_or_revision_exits_2_listing_what_exists(run):
    assert run("db", "upgrade").exit_code == 0
    empty = run("board", "show", "A17")
    assert empty.exit_code == 2 and "unknown board 'A17'; no boards are registered yet" in empty.stderr
    run("board", "add", "B2", *CHESS)
    run("board", "add", "A17", *CHESS)
    unknown = run("board", "show", "C3")
    assert unknown.exit_code == 2
    assert "Error: unknown board 'C3'; known: A17, B2" in unknown.stderr
    assert "Hint: see `calibctl board list`" in unknown.stderr
    no_rev = run("board", "show", "A17@4")
    assert no_rev.exit_code == 2 and "board A17 has no revision 4; revisions: 1" in no_rev.stderr
    bad_ref = run("board", "show", "A17@x")
    assert bad_ref.exit_code == 2 and "'A17@x' is not a board reference" in bad_ref.stderr


def test_changing_the_pattern_of_an_existing_name_is_refused(run):
    run("board", "add", "A17", *CHESS)
    result = run("board", "add", "A17", "--cols", "8", "--rows", "6", "--square-mm", "25")
    assert result.exit_code == 2
    assert (
        "board A17@1 is a 9x6 chessboard; a new revision may only re-measure it, but cols differ"
        in result.stderr
    )


def test_empty_registry_lists_nothing(run):
    assert run("db", "upgrade").exit_code == 0
    result = run("board", "list")
    assert result.exit_code == 0 and "no boards registered yet" in result.stdout


def test_a_square_size_given_in_metres_is_registered_but_warned_about(run):
    """0.025 typed for 25 mm: intrinsics do not notice, every distance is 1000x off; say so at once."""
    result = run(
        "board",
        "add",
        "M1",
        "--cols",
        "9",
        "--rows",
        "6",
        "--square-mm",
        "0.025",
        "--uncertainty-mm",
        "0.0001",
        *MEASURED[2:],
    )
    assert result.exit_code == 0, result.output
    assert "warning: M1@1 has a 0.025 mm square: --square-mm takes millimetres" in result.stderr
    assert "register it again with --square-mm 25;" in result.stderr
    assert "square 0.025 mm ± 0.0001 mm (1σ)" in result.stdout  # not "± 0.000 mm"
    one_mm = run("board", "add", "U1", "--cols", "9", "--rows", "6", "--square-mm", "1.0", *MEASURED)
    assert one_mm.exit_code == 0 and "--square-mm takes millimetres" not in one_mm.stderr
