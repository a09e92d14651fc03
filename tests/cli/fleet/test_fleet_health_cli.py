"""calibctl fleet ingest | trends: good and refused lines (all or nothing per file), dedup, --json, db
verify."""

from __future__ import annotations

import json
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from calibctl.workflows.fleet import health
from tests.artifacts.factories import calibration
from tests.store.documents import fleet_event, health_report

NOW = datetime.now(UTC).replace(microsecond=0)


def _report(i: int, **fields: object) -> dict:
    doc = {
        "source_id": f"amr-1/{i}",
        "serial": "CAM-A",
        "robot": "amr-1",
        "kind": "check",
        "time": (NOW - timedelta(days=30 - i)).isoformat(),
        "rms_px": 0.30 + 0.01 * i,
        "verdict": "pass",
        "temperature_c": 15.0 + 2 * i,
    }
    return {**doc, **fields}


def _write(path: Path, lines: list[dict | str]) -> Path:
    path.write_text("".join((line if isinstance(line, str) else json.dumps(line)) + "\n" for line in lines))
    return path


@pytest.fixture
def db(sqlite_url: str) -> str:
    with Store.open(sqlite_url, create=True) as store:
        store.add_fleet_event(fleet_event("register", robot="amr-1", serials=["CAM-A"]))
        store.add_fleet_event(fleet_event("register", robot="amr-2", serials=["CAM-B"]))
    return sqlite_url


def _run(db: str, *args: str):
    return CliRunner().invoke(app, ["--db", db, "fleet", *args])


def _stored(db: str) -> int:
    with Store.open(db, create=False) as store:
        return store.health_report_count()


def test_ingest_then_trends_in_text_and_json(db: str, tmp_path: Path) -> None:
    reports = [_report(i) for i in range(10)]
    reports += [
        _report(
            i,
            source_id=f"amr-1/td{i}",
            kind="timeoffset",
            rms_px=None,
            verdict=None,
            td_ms=1.0 + 0.864 * i,
            sigma_ms=0.1,
        )
        for i in range(10)
    ]
    reports += [_report(0, source_id="amr-2/0", serial="CAM-B", robot="amr-2", rms_px=0.9, verdict="fail")]
    result = _run(db, "ingest", str(_write(tmp_path / "day.jsonl", reports)))
    assert result.exit_code == 0, result.output
    assert "21 report(s) stored" in result.stdout and _stored(db) == 21
    text = _run(db, "trends", "CAM-A")
    assert text.exit_code == 0, text.output
    assert "CAM-A: 10 check, 10 timeoffset" in text.stdout
    assert "RMS vs temperature: +0.0050 +- 0.0000 px/degC (n 10)" in text.stdout
    assert "td vs time: +0.01 +- 0.00 ppm over 9.0 days (n 10)" in text.stdout  # 0.864 ms/day = 0.01 ppm
    assert "rank 1 of 2" in text.stdout
    doc = json.loads(_run(db, "trends", "CAM-A", "--json").stdout)
    assert doc["rms_vs_temperature_px_per_c"]["slope"] == pytest.approx(0.005)
    assert doc["td_drift_ppm"]["slope"] == pytest.approx(0.01)
    assert doc["fleet"]["worst"] == "CAM-B" and doc["check_verdicts"] == {"pass": 10}
    assert CliRunner().invoke(app, ["--db", db, "db", "verify"]).exit_code == 0


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ("{not json", "malformed JSON"),
        (json.dumps(_report(9, rms_px=float("nan"))), "rms_px"),
        (json.dumps(_report(9, td_ms=float("inf"))), "td_ms"),
        (_report(9, time=(NOW + timedelta(minutes=30)).isoformat()), "more than 5 minutes in the future"),
        (_report(9, serial="CAM-B"), "unknown serial CAM-B: robot amr-1 carries CAM-A"),
        (_report(9, robot="amr-9"), "robot amr-9 is not registered"),
        (_report(1), "source id amr-1/1 appears twice in this batch"),
        (_report(9, kind="gauge"), "a gauge report needs ratio, sigma"),
        (_report(9, verdict="maybe"), "verdict is pass or fail"),
        (_report(9, td_ms=3.0), "a check report carries rms_px, verdict, temperature_c, not td_ms"),
        ("x" * 5000, "longer than a report"),
        (_report(9, rms_px=True), "rms_px: Value error, must be a number, not bool True"),
        (_report(9, rms_px="0.3"), "rms_px: Value error, must be a number, not str 0.3"),
        (_report(9, time="0001-01-01T00:00:00+00:00"), "is before 2000-01-01"),
    ],
    ids=lambda value: (
        value if isinstance(value, str) and len(value) < 80 and not value.startswith("{") else None
    ),
)
def test_a_refused_line_is_named_exits_1_and_its_file_writes_nothing(
    db: str, tmp_path: Path, bad: object, message: str
) -> None:
    bad_file = _write(tmp_path / "bad.jsonl", [_report(0), _report(1), bad])  # type: ignore[list-item]
    good_file = _write(tmp_path / "good.jsonl", [_report(5), _report(6)])
    result = _run(db, "ingest", str(bad_file), str(good_file))
    assert result.exit_code == 1, result.output
    assert "bad.jsonl:3: " in result.stderr and message in result.stderr, result.stderr
    assert "bad.jsonl:1" not in result.stderr and "Traceback" not in result.output
    assert (
        "refused, nothing stored (1 bad line(s))" in result.stdout and "2 report(s) stored" in result.stdout
    )
    assert _stored(db) == 2  # the good file only


def test_a_report_sent_twice_is_refused_the_second_time(db: str, tmp_path: Path) -> None:
    path = _write(tmp_path / "r.jsonl", [_report(0), _report(1)])
    assert _run(db, "ingest", str(path)).exit_code == 0
    again = _run(db, "ingest", str(path), "--json")
    assert again.exit_code == 1
    doc = json.loads(again.stdout)
    assert doc["stored"] == 0 and doc["files"][0]["refused"][1] == {
        "line": 2,
        "why": "duplicate report: source id amr-1/1 is stored already",
    }
    assert _stored(db) == 2


def test_unreadable_inputs_exit_2(db: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    missing = _run(db, "ingest", str(tmp_path / "nope.jsonl"))
    assert missing.exit_code == 2 and "nope.jsonl" in missing.stderr
    monkeypatch.setattr(health, "MAX_LINES", 3)
    many = _run(db, "ingest", str(_write(tmp_path / "many.jsonl", [_report(i) for i in range(4)])))
    assert many.exit_code == 2 and "more than 3 reports in one file" in many.stderr
    none = _run(db, "trends", "CAM-Z")
    assert none.exit_code == 2 and "no health reports for CAM-Z" in none.stderr
    assert _stored(db) == 0


def test_a_report_dated_before_its_serials_first_calibration_is_refused(db: str, tmp_path: Path) -> None:
    with Store.open(db) as store:  # CAM-A calibrated 2026-03-11 09:30 UTC
        store.add_artifact(
            calibration(serial="CAM-A"), activate=True, actor="qa", station="st1", reason="solved"
        )
    early = _report(0, time="2026-03-11T09:29:59+00:00")
    result = _run(db, "ingest", str(_write(tmp_path / "early.jsonl", [early, _report(1)])))
    assert result.exit_code == 1, result.output
    assert (
        "early.jsonl:1: time 2026-03-11T09:29:59+00:00 is before CAM-A's first calibration" in result.stderr
    )
    assert _stored(db) == 0
    on_time = _report(0, time="2026-03-11T09:30:00+00:00")
    assert _run(db, "ingest", str(_write(tmp_path / "ok.jsonl", [on_time]))).exit_code == 0


def test_store_refuses_bad_batches_whole_on_both_backends(db_url: str) -> None:
    with Store.open(db_url, create=True) as store:
        store.add_fleet_event(fleet_event("register", robot="amr-1", serials=["CAM-A"]))
        assert store.add_health_reports([health_report("CAM-A", robot="amr-1", source_id="a")]) == []
        problems = store.add_health_reports(
            [
                health_report("CAM-A", robot="amr-1", source_id="b"),
                health_report("CAM-A", robot="amr-1", source_id="a"),
            ]
        )
        assert problems == [(1, "duplicate report: source id a is stored already")]
        assert store.health_report_count() == 1
        rows = store.health_rows("CAM-A")
        assert len(rows) == 1 and rows[0].rms_px == 0.3 and rows[0].at.tzinfo is not None
        assert store.fleet_check_rms() == {"CAM-A": (pytest.approx(0.3), 1)}
