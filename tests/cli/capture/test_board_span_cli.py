"""The gauge at the desk: `board add --span-mm` (a second, independent measurement) and its lint warning."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.artifacts.board import BoardRevision
from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board

RUNNER = CliRunner()
MEASURED = [
    "--uncertainty-mm",
    "0.02",
    "--instrument",
    "calipers",
    "--measured-by",
    "anna",
    "--measured-on",
    "2026-03-11",
]
SPAN = ["--span-uncertainty-mm", "0.1", "--span-instrument", "steel rule"]


def add(db: str, square: str, *extra: str):
    return RUNNER.invoke(
        app,
        ["--db", db, "board", "add", "A17", "--cols", "9", "--rows", "6", "--square-mm", square, *extra],
        terminal_width=120,
    )


def test_a_square_size_the_span_confirms_is_measured(sqlite_url: str) -> None:
    done = add(sqlite_url, "25.0", *MEASURED, "--span-mm", "200.05", *SPAN, "--json")
    assert done.exit_code == 0, done.output
    m = json.loads(done.stdout)["measurement"]
    assert m["status"] == "measured"
    assert m["span"]["span_m"] == pytest.approx(0.20005) and m["span"]["squares"] == 8
    shown = RUNNER.invoke(app, ["--db", sqlite_url, "board", "show", "A17"], terminal_width=120)
    assert "span 200.050 mm over 8 squares agrees" in shown.stdout and "steel rule" in shown.stdout


def test_the_23mm_typo_is_refused_naming_both_numbers(sqlite_url: str) -> None:
    done = add(sqlite_url, "23.0", *MEASURED, "--span-mm", "200", *SPAN)
    assert done.exit_code == 2
    assert "--square-mm 23 x 8 squares = 184.00 mm, but --span-mm 200" in done.stderr
    assert "the square size or the span is wrong" in done.stderr and "25.000 mm squares" in done.stderr
    with Store.open(sqlite_url) as store:
        assert store.list_boards() == []


@pytest.mark.parametrize(("span", "slip"), [("20.0", "0.1x"), ("0.2", "0.001x"), ("2000", "10x")])
def test_a_span_in_the_wrong_units_is_named_as_such(sqlite_url: str, span: str, slip: str) -> None:
    done = add(sqlite_url, "25.0", *MEASURED, "--span-mm", span, *SPAN)
    assert done.exit_code == 2
    assert f"is {slip} that: wrong units" in done.stderr


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--span-mm", "200"], "a span measurement needs --span-uncertainty-mm, --span-instrument"),
        (["--span-instrument", "rule"], "give --span-mm too"),
        (["--span-mm", "200", *SPAN, "--span-squares", "9"], "--span-squares 9 must be between 1 and 8"),
    ],
)
def test_an_incomplete_span_is_a_usage_error(sqlite_url: str, extra: list[str], message: str) -> None:
    done = add(sqlite_url, "25.0", *MEASURED, *extra)
    assert done.exit_code == 2 and message in done.stderr


def test_a_span_cannot_back_a_nominal_square(sqlite_url: str) -> None:
    done = add(sqlite_url, "25.0", "--span-mm", "200", *SPAN)
    assert done.exit_code == 2 and "this one is nominal" in done.stderr


def test_one_measurement_is_measured_single_and_lint_warns(sqlite_url: str, tmp_path: Path) -> None:
    done = add(sqlite_url, "25.0", *MEASURED, "--json")
    assert json.loads(done.stdout)["measurement"]["status"] == "measured-single"
    art = calibration()
    single = art.board.measurement.model_copy(update={"status": "measured-single"})
    path = tmp_path / "single.json"
    path.write_text(
        art.model_copy(update={"board": art.board.model_copy(update={"measurement": single})})
        .sealed()
        .model_dump_json()
    )
    linted = RUNNER.invoke(app, ["lint", str(path), "--format", "json"])
    findings = [
        f for f in json.loads(linted.stdout)["results"][0]["findings"] if f["rule"].startswith("square-size")
    ]
    assert [(f["rule"], f["severity"]) for f in findings] == [("square-size-single", "warning")]
    assert linted.exit_code == 0, linted.output  # a warning, not an error


def test_a_board_registered_before_the_span_still_reads_and_keeps_its_bytes() -> None:
    old = measured_board()  # status measured, no span: what every board stored before this change is
    text = old.model_dump_json()
    assert '"span"' not in text
    assert BoardRevision.model_validate_json(text) == old
