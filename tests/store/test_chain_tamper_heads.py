"""The two gaps no `db verify` mode saw: immutability triggers dropped and left dropped, and a forged row
given an id below the kept head's (``--since`` looked only at higher ids; it now takes every row past the
head's *positions*, whatever its id)."""

from __future__ import annotations

import sqlite3

import pytest
from sqlalchemy.engine import make_url
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store import triggers
from calibctl.store.engine import make_engine
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.store.tamper import run_underneath
from tests.store.test_chain_tamper import _select, history, problems_of  # noqa: F401 - the fixture

WHO = {"actor": "qa", "station": "st1"}


def _dialect(url: str) -> str:
    engine = make_engine(url)
    try:
        return engine.dialect.name
    finally:
        engine.dispose()


def test_a_fresh_store_has_every_trigger(history: str):
    assert problems_of(history) == []


def test_triggers_dropped_and_left_dropped(history: str):
    run_underneath(
        history, "UPDATE activation_events SET reason = reason WHERE id = 0", keep_triggers_dropped=True
    )
    expected = triggers.expected(_dialect(history))
    problems = problems_of(history)
    assert len(problems) == len(expected) and all(
        "the database no longer refuses changes" in p for p in problems
    )
    assert any(p.startswith("the immutability trigger trg_calibration_artifacts_") for p in problems)
    res = CliRunner().invoke(app, ["--db", history, "db", "verify"])
    assert res.exit_code == 1
    assert "is missing: the database no longer refuses changes to that table" in res.stdout


def test_a_trigger_disabled_or_defanged_is_named(history: str):
    if _dialect(history) == "sqlite":  # same name, refuses nothing
        name = "trg_calibration_artifacts_no_update"
        conn = sqlite3.connect(make_url(history).database, isolation_level=None)
        try:
            conn.execute(f"DROP TRIGGER {name}")
            conn.execute(
                f"CREATE TRIGGER {name} BEFORE UPDATE ON calibration_artifacts WHEN 0 "
                "BEGIN SELECT RAISE(ABORT, 'calibration artifacts are immutable'); END"
            )
        finally:
            conn.close()
        verb = "changed"
    else:
        name = "trg_calibration_artifacts_immutable"
        run_underneath(history, f"ALTER TABLE calibration_artifacts DISABLE TRIGGER {name}")
        verb = "disabled"
    assert problems_of(history) == [
        f"the immutability trigger {name} on calibration_artifacts was {verb}: the "
        "database no longer refuses changes to that table"
    ]


def test_since_head_sees_a_forged_row_with_an_id_below_the_head(history: str):
    with Store.open(history) as store:
        head = store.verify().head()
    run_underneath(
        history,
        "INSERT INTO activation_events (id, serial, version, previous_version, kind, actor, station, "
        "at, reason) VALUES (0, 'CAM-1', 3, 1, 'rollback', 'qa', 'st1', '2026-11-23 08:00:00', 'x')",
    )
    with Store.open(history) as store:
        problems = store.verify(since=head).problems
    assert (
        "activation event 0 (CAM-1@3, rollback) has no chain hash: it was inserted outside calibctl"
        in problems
    )


def test_since_head_sees_a_row_appended_after_the_head_with_a_low_id(history: str):
    """A new version appended at the next position of its chain, given id 0: it is past the head's
    position."""
    with Store.open(history) as store:
        head = store.verify().head()
        store.add_artifact(calibration(serial="CAM-2", fx=790.0), activate=False, reason="solved", **WHO)
        assert store.verify(since=head).problems == []
    (last,) = _select(history, "SELECT max(id) FROM calibration_artifacts")[0]
    run_underneath(
        history,
        f"UPDATE calibration_artifacts SET id = 0 WHERE id = {last}",
        "UPDATE calibration_artifacts SET operator = 'mallory' WHERE id = 0",
    )
    with Store.open(history) as store:
        problems = store.verify(since=head).problems
    # it moved the head's position of CAM-2 (so its digest fails), and every row is then checked
    assert problems[0].startswith("the history up to the given chain head was rewritten or truncated")
    assert "CAM-2@2 was changed after it was written (its chain hash no longer matches)" in problems


def test_since_head_sees_a_second_record_at_an_old_position(history: str):
    with Store.open(history) as store:
        head = store.verify().head()
    index = "ix_activation_events_chain_seq"
    (prev, digest) = _select(
        history, "SELECT chain_prev, chain_hash FROM activation_events WHERE chain_seq = 2"
    )[0]
    drop = f"DROP INDEX {index}" if _dialect(history) == "sqlite" else f"DROP INDEX IF EXISTS {index}"
    run_underneath(
        history,
        drop,
        "INSERT INTO activation_events (id, serial, version, previous_version, kind, actor, "
        "station, at, reason, chain_seq, chain_prev, chain_hash) VALUES (0, 'CAM-1', 3, 1, "
        "'rollback', 'qa', 'st1', '2026-11-23 08:00:00', 'x', 2, %s, %s)",
        params=(prev, digest),
    )
    with Store.open(history) as store:
        problems = store.verify(since=head).problems
    assert (
        "position 2 of the event chain is held by more than one record: one was added outside calibctl"
        in problems
    )


def test_since_head_sees_a_forged_row_at_position_0(history: str):
    """A row given position 0 (below every position a head holds) and an id below the head's: no position
    after the head, no second record at a position, yet it is no part of any chain."""
    with Store.open(history) as store:
        head = store.verify().head()
    run_underneath(
        history,
        "INSERT INTO activation_events (id, serial, version, previous_version, kind, actor, "
        "station, at, reason, chain_seq, chain_prev, chain_hash) VALUES (0, 'CAM-1', 3, 1, "
        "'rollback', 'qa', 'st1', '2026-11-23 08:00:00', 'x', 0, NULL, %s)",
        params=("0" * 64,),
    )
    forged = "activation event 0 (CAM-1@3, rollback) is at chain position 0, before the first"
    with Store.open(history) as store:
        assert forged in store.verify(since=head).problems[0]
        assert forged in store.verify().problems[0]


@pytest.mark.parametrize("dropped", [False, True])
def test_since_head_checks_the_triggers_too(history: str, dropped: bool):
    with Store.open(history) as store:
        head = store.verify().head()
    run_underneath(
        history, "UPDATE activation_events SET reason = reason WHERE id = 0", keep_triggers_dropped=dropped
    )
    with Store.open(history) as store:
        problems = store.verify(since=head).problems
    assert bool(problems) is dropped
