"""The sqlite3 read path answers exactly what Store answers, and leaves every other case to Store."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from calibctl.artifacts.check import CheckEvent, RegionCheck
from calibctl.artifacts.common import utc_now
from calibctl.errors import CalibctlError, DatabaseOutOfDateError, NotFoundError, UnverifiedRecord
from calibctl.signing import create_key
from calibctl.store import migrate, sqlite_reads
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.tamper import forge_activation, patch_stored_bytes

SERIAL = "CAM-0001"


def _check(art, passed: bool) -> CheckEvent:
    region = RegionCheck(
        region="overall",
        check_rms_px=0.2,
        reference_rms_px=0.19,
        ratio=1.05,
        limit=1.3,
        corners=540,
        tested=True,
        passed=passed,
    )
    return CheckEvent(
        check_id=("a" if passed else "b") * 12,
        serial=art.serial,
        version=art.version,
        calibration_sha256=art.content_sha256,
        source="folder /tmp/x",
        station="st1",
        operator="qa",
        at=utc_now(),
        image_size=art.image_size,
        images=10,
        views=["v0.png"],
        view_rms_px=[0.2],
        regions=[region],
        alpha=0.01,
        passed=passed,
    )


@pytest.fixture
def store_url(tmp_path: Path) -> str:
    """Two boards, three versions (one rejected), a rollback, two checks, every record signed."""
    url = f"sqlite:///{tmp_path / 'store.db'}"
    signer = create_key(tmp_path / "key.pem")
    with Store.open(url, signer=signer) as store:
        store.add_board(measured_board("A17"))
        store.add_board(measured_board("A17", square_mm=25.05))
        store.add_board(measured_board("B2"))
        v1 = store.add_artifact(
            calibration(serial=SERIAL), activate=True, actor="qa", station="st1", reason="solved"
        )
        store.add_artifact(
            calibration(serial=SERIAL, version=2, status="rejected"),
            activate=False,
            actor="qa",
            station="st1",
            reason="solved",
        )
        store.add_artifact(
            calibration(serial=SERIAL, version=3), activate=True, actor="qa", station="st1", reason="solved"
        )
        store.rollback(SERIAL, 1, reason="v3 drifted", actor="qa", station="st1")
        store.add_check(_check(v1, True))
        store.add_check(_check(v1, False))
        store.add_artifact(
            calibration(serial="CAM-IDLE", status="rejected"),
            activate=False,
            actor="qa",
            station="st1",
            reason="solved",
        )
    return url


READS = {
    "list_artifacts": lambda s: s.list_artifacts(SERIAL),
    "active_version": lambda s: s.active_version(SERIAL),
    "events": lambda s: s.events(SERIAL),
    "checks": lambda s: s.checks(SERIAL),
    "get_artifact active": lambda s: s.get_artifact(SERIAL),
    "get_artifact @2": lambda s: s.get_artifact(SERIAL, 2),
    "list_boards": lambda s: s.list_boards(),
}


def _no_fallback():
    raise AssertionError("the sqlite3 reader fell back to Store")


@pytest.mark.parametrize("name", READS)
def test_each_read_is_served_by_sqlite3_and_equals_the_store_read(store_url: str, name: str) -> None:
    with Store.open(store_url, create=False) as store:
        expected = READS[name](store)
    assert sqlite_reads.read(store_url, READS[name], _no_fallback) == expected
    assert expected not in (None, [])  # the store holds something for every read


def test_signatures_and_times_come_back_as_the_store_returns_them(store_url: str) -> None:
    art = sqlite_reads.read(store_url, lambda s: s.get_artifact(SERIAL, 3), _no_fallback)
    assert art.signature is not None and art.signature.record_sha256
    events = sqlite_reads.read(store_url, lambda s: s.events(SERIAL), _no_fallback)
    assert [e.kind for e in events][-1] == "rollback" and all(e.at.tzinfo is not None for e in events)


def _error_of(work) -> CalibctlError:
    with pytest.raises(CalibctlError) as exc:
        work()
    return exc.value


@pytest.mark.parametrize(
    "work",
    [
        lambda s: s.list_artifacts("CAM-UNKNOWN"),
        lambda s: s.get_artifact(SERIAL, 9),
        lambda s: s.get_artifact("CAM-IDLE"),  # nothing active
    ],
)
def test_what_sqlite3_does_not_serve_is_read_by_the_store_with_its_errors(store_url: str, work) -> None:
    def via_store():
        with Store.open(store_url, create=False) as store:
            return work(store)

    expected = _error_of(via_store)
    got = _error_of(lambda: sqlite_reads.read(store_url, work, lambda: Store.open(store_url, create=False)))
    assert isinstance(expected, NotFoundError)
    assert (type(got), got.message, got.hint) == (type(expected), expected.message, expected.hint)


def test_a_tampered_artifact_is_refused_by_the_sqlite3_path_too(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'one.db'}"
    with Store.open(url) as store:
        store.add_artifact(
            calibration(serial=SERIAL), activate=True, actor="qa", station="st1", reason="solved"
        )
    patch_stored_bytes(url, "calibration_artifacts", '"operator":"op"', '"operator":"OP"')
    with pytest.raises(UnverifiedRecord) as exc:
        sqlite_reads.read(url, lambda s: s.list_artifacts(SERIAL), _no_fallback)
    assert (
        exc.value.message == f"{SERIAL}@1 was changed after it was written (its chain hash no longer matches)"
    )


def test_a_forged_activation_of_a_rejected_version_is_left_to_the_store(store_url: str) -> None:
    forge_activation(store_url, SERIAL, 2)
    with pytest.raises(UnverifiedRecord) as exc:
        sqlite_reads.read(
            store_url, lambda s: s.get_artifact(SERIAL), lambda: Store.open(store_url, create=False)
        )
    assert "which is not accepted" in exc.value.message


def test_an_out_of_date_store_is_left_to_the_store(store_url: str) -> None:
    older = migrate.known_revisions()[-2]
    conn = sqlite3.connect(store_url.removeprefix("sqlite:///"), isolation_level=None)
    conn.execute("UPDATE alembic_version SET version_num = ?", (older,))
    conn.close()
    with pytest.raises(DatabaseOutOfDateError):
        sqlite_reads.read(store_url, lambda s: s.list_boards(), lambda: Store.open(store_url, create=False))


@pytest.mark.parametrize(
    "url",
    [
        "sqlite://",
        "sqlite:///:memory:",
        "postgresql://u@h/db",
        "sqlite:///{}?mode=ro",
        "sqlite:///{}/absent.db",
    ],
)
def test_other_urls_and_absent_files_are_not_served(tmp_path: Path, url: str) -> None:
    used = []

    class Marker:
        def __enter__(self):
            used.append(True)
            return self

        def __exit__(self, *exc):
            return False

        def list_boards(self):
            return ["from the store"]

    assert sqlite_reads.read(url.format(tmp_path), lambda s: s.list_boards(), Marker) == ["from the store"]
    assert used == [True] and not (tmp_path / "absent.db").exists()


def test_a_lock_timeout_setting_is_left_to_the_store_which_applies_and_checks_it(
    store_url: str, monkeypatch
) -> None:
    from calibctl.errors import UsageError
    from calibctl.store import engine

    assert sqlite_reads.LOCK_TIMEOUT_S == engine.DEFAULT_SQLITE_LOCK_TIMEOUT_S
    assert sqlite_reads.LOCK_TIMEOUT_ENV == engine.LOCK_TIMEOUT_ENV
    monkeypatch.setenv(engine.LOCK_TIMEOUT_ENV, "soon")
    with pytest.raises(UsageError, match="is not a number of seconds"):
        sqlite_reads.read(store_url, lambda s: s.list_boards(), lambda: Store.open(store_url, create=False))


def test_a_read_leaves_the_store_folder_as_it_found_it(store_url: str, tmp_path: Path) -> None:
    before = sorted(p.name for p in tmp_path.iterdir())
    sqlite_reads.read(store_url, READS["list_artifacts"], _no_fallback)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no -wal / -shm left behind by the read
    assert "store.db" in before and not [name for name in before if name.endswith(("-wal", "-shm"))]


EDITS_UNDERNEATH = {
    "station": "UPDATE calibration_artifacts SET station = 'elsewhere' WHERE version = 3",
    "stored_at": "UPDATE calibration_artifacts SET stored_at = '2020-01-01 00:00:00.000000' WHERE version "
    "= 3",
    "payload": 'UPDATE calibration_artifacts SET payload = replace(payload, \'"operator":"op"\', '
    '\'"operator":"OP"\') '
    "WHERE version = 3",
    "content_sha256": "UPDATE calibration_artifacts SET content_sha256 = substr(content_sha256, 2) || '0' "
    "WHERE version = 3",
    "chain_hash cleared": "UPDATE calibration_artifacts SET chain_hash = NULL WHERE version = 3",
}


def _outcome(work):
    try:
        return work()
    except CalibctlError as exc:
        return (type(exc), exc.message)


@pytest.mark.parametrize("edit", EDITS_UNDERNEATH)
@pytest.mark.parametrize("read", ["get_artifact", "list_artifacts"])
def test_a_column_edited_underneath_gets_the_same_answer_from_both_paths(
    store_url: str, edit: str, read: str
) -> None:
    """A tripwire: whatever check Store's reads make on a calibration row (the record's chain hash over every
    column, then the columns against the document), the sqlite3 path must make too."""
    from tests.store.tamper import run_underneath

    run_underneath(store_url, EDITS_UNDERNEATH[edit])
    served = _same_on_both_paths(store_url, read)
    assert served[0] is UnverifiedRecord and f"{SERIAL}@3 " in served[1]


def _same_on_both_paths(store_url: str, read: str):
    """The outcome of reading version 3 through the sqlite3 path, checked equal to Store's."""
    work = {
        "get_artifact": lambda s: s.get_artifact(SERIAL, 3),
        "list_artifacts": lambda s: s.list_artifacts(SERIAL),
    }[read]

    def via_store():
        with Store.open(store_url, create=False) as store:
            return work(store)

    served = _outcome(lambda: sqlite_reads.read(store_url, work, _no_fallback))
    assert served == _outcome(via_store)
    return served


def test_a_check_event_edited_underneath_gets_the_same_answer_from_both_paths(store_url: str) -> None:
    from tests.store.tamper import run_underneath

    run_underneath(
        store_url,
        'UPDATE check_events SET payload = replace(payload, \'"station":"st1"\', '
        '\'"station":"st9"\') WHERE passed = 0',
    )

    def via_store():
        with Store.open(store_url, create=False) as store:
            return store.checks(SERIAL)

    served = _outcome(lambda: sqlite_reads.read(store_url, lambda s: s.checks(SERIAL), _no_fallback))
    assert served == _outcome(via_store)
    assert served[0] is UnverifiedRecord and "does not match its recorded sha256" in served[1]


def test_the_sqlite3_rows_of_calibrations_hold_the_columns_the_store_hashes(store_url: str) -> None:
    """The chain hash is taken over every mapped column: a ``SELECT *`` row must hold exactly those."""
    from calibctl.store.models import ArtifactRow

    conn = sqlite3.connect(store_url.removeprefix("sqlite:///"))
    try:
        names = {r[1] for r in conn.execute("PRAGMA table_info(calibration_artifacts)").fetchall()}
    finally:
        conn.close()
    assert names == {c.name for c in ArtifactRow.__table__.columns}


@pytest.mark.parametrize("garbage", ["'garbage'", "12345"])
@pytest.mark.parametrize("read", ["get_artifact", "list_artifacts"])
def test_an_unparseable_date_edited_underneath_is_a_tampered_record_on_both_paths(
    store_url: str, garbage: str, read: str
) -> None:
    """SQLite keeps date-times as text: one edited into something that is no date fails in SQLAlchemy's own
    parser, before any check of calibctl's; a refused record all the same (UnverifiedRecord), no traceback."""
    from tests.store.tamper import run_underneath

    run_underneath(store_url, f"UPDATE calibration_artifacts SET stored_at = {garbage} WHERE version = 3")
    served = _same_on_both_paths(store_url, read)
    assert (
        served[0] is UnverifiedRecord
        and "is unreadable: the database was edited outside calibctl" in served[1]
    )


def test_an_unparseable_date_fails_db_verify_and_history_with_a_message(store_url: str) -> None:
    from typer.testing import CliRunner

    from calibctl.cli.main import app
    from tests.store.tamper import run_underneath

    run_underneath(store_url, "UPDATE calibration_artifacts SET stored_at = 'garbage' WHERE version = 3")
    for args, code in ((["db", "verify"], 1), (["history", SERIAL], 2), (["show", f"{SERIAL}@3"], 2)):
        result = CliRunner().invoke(app, ["--db", store_url, *args])
        assert result.exit_code == code, result.output
        assert "a stored date and time ('garbage') is unreadable" in result.output
        assert not isinstance(result.exception, ValueError | TypeError)
