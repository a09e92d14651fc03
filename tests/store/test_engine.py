"""URLs, connection settings and what an unreachable or unusable database looks like to the user."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import text
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.errors import DatabaseError, UsageError
from calibctl.store.engine import display_url, lock_timeout_s, make_engine, normalise_url
from calibctl.store.repository import Store

UNREACHABLE = "postgresql://calib:s3cret@127.0.0.1:1/calibctl"  # nothing listens on port 1


@pytest.mark.parametrize(
    ("given", "expected"),
    [
        ("postgresql://u@h/db", "postgresql+psycopg://u@h/db"),
        ("postgres://u@h:5433/db", "postgresql+psycopg://u@h:5433/db"),
        ("postgresql+psycopg://u@h/db", "postgresql+psycopg://u@h/db"),
        ("sqlite:///calibctl.db", "sqlite:///calibctl.db"),
        ("data/line3.db", "sqlite:///data/line3.db"),
    ],
)
def test_urls_are_normalised(given: str, expected: str):
    assert normalise_url(given) == expected


@pytest.mark.parametrize("url", ["mysql://u@h/db", "oracle+cx://x", ""])
def test_unsupported_urls_are_refused(url: str):
    with pytest.raises(UsageError, match="unsupported database URL scheme|the database URL is empty") as info:
        normalise_url(url)
    assert info.value.exit_code == 2


def test_passwords_never_appear_in_the_displayed_url():
    assert display_url(UNREACHABLE) == "postgresql://calib:***@127.0.0.1:1/calibctl"
    assert "s3cret" not in display_url("mysql://calib:s3cret@h/db")


@pytest.mark.parametrize(("raw", "expected"), [(None, 10.0), ("", 10.0), ("0.5", 0.5), ("30", 30.0)])
def test_lock_timeout_comes_from_the_environment(raw, expected):
    assert lock_timeout_s({} if raw is None else {"CALIBCTL_DB_LOCK_TIMEOUT_S": raw}) == expected


@pytest.mark.parametrize("raw", ["soon", "0", "-1", "1e9", "nan"])
def test_a_bad_lock_timeout_is_refused(raw: str):
    with pytest.raises(UsageError, match=f"CALIBCTL_DB_LOCK_TIMEOUT_S='{raw}' is not a number of seconds"):
        lock_timeout_s({"CALIBCTL_DB_LOCK_TIMEOUT_S": raw})


def test_sqlite_connections_use_wal_foreign_keys_and_a_bounded_busy_wait(sqlite_url: str, monkeypatch):
    monkeypatch.setenv("CALIBCTL_DB_LOCK_TIMEOUT_S", "2.5")
    engine = make_engine(sqlite_url)
    try:
        with engine.connect() as conn:
            pragmas = {
                name: conn.execute(text(f"PRAGMA {name}")).scalar_one()
                for name in ("journal_mode", "foreign_keys", "busy_timeout")
            }
    finally:
        engine.dispose()
    assert pragmas == {"journal_mode": "wal", "foreign_keys": 1, "busy_timeout": 2500}


def test_an_unreachable_postgresql_is_a_clear_database_error():
    with pytest.raises(DatabaseError) as info:
        Store.open(UNREACHABLE)
    message = info.value.message
    assert message.startswith("cannot connect to the database postgresql://calib:***@127.0.0.1:1/calibctl: ")
    assert "s3cret" not in str(info.value) and info.value.exit_code == 2
    assert "CALIBCTL_DB" in (info.value.hint or "")


def test_the_cli_exits_2_when_the_database_is_unreachable():
    result = CliRunner().invoke(app, ["--db", UNREACHABLE, "board", "list"])
    assert result.exit_code == 2
    assert (
        "Error: cannot connect to the database postgresql://calib:***@127.0.0.1:1/calibctl" in result.stderr
    )
    assert "s3cret" not in result.output and "Traceback" not in result.output


def test_a_sqlite_file_in_a_missing_directory_is_a_clear_database_error(tmp_path: Path):
    url = f"sqlite:///{tmp_path / 'no' / 'such' / 'dir' / 'calibctl.db'}"
    with pytest.raises(
        DatabaseError, match="cannot open the SQLite database sqlite:///.*/no/such/dir/calibctl.db"
    ):
        Store.open(url)


def test_a_file_that_is_not_a_database_is_refused(tmp_path: Path):
    path = tmp_path / "notes.db"
    path.write_text("these are not the tables you are looking for\n" * 200)
    with pytest.raises(DatabaseError, match="notes.db is not a SQLite database"):
        Store.open(f"sqlite:///{path}")
    assert path.read_text().startswith("these are not")


@pytest.mark.postgres
def test_store_url_hides_the_password(pg_url: str):
    with_password = pg_url.replace("postgres@", "postgres:hunter2@", 1)  # trust auth ignores it
    with Store.open(with_password) as store:
        assert store.url == pg_url.replace("postgres@", "postgres:***@", 1)
        assert store.backend == "postgresql"


@pytest.mark.postgres
def test_a_missing_postgresql_database_is_a_clear_database_error(pg_server: str):
    url = pg_server.rsplit("/", 1)[0] + "/calibctl_no_such_database"
    with pytest.raises(
        DatabaseError,
        match=r'cannot connect to the database .*/calibctl_no_such_database: .*"calibctl_no_such_database" '
        r"does not exist",
    ):
        Store.open(url)


def test_sqlite_writers_wait_longer_by_default_than_postgresql_row_locks():
    # SQLite's busy handler is not fair under many writers (see calibctl.store.engine); row locks are.
    assert lock_timeout_s({}, backend="sqlite") == 60.0 and lock_timeout_s({}, backend="postgresql") == 10.0
    assert lock_timeout_s({"CALIBCTL_DB_LOCK_TIMEOUT_S": "5"}, backend="sqlite") == 5.0


@pytest.mark.parametrize(
    ("driver_message", "words"),
    [
        (
            "database or disk is full",
            "the disk of the store sqlite:///x.db is full; this transaction was not stored",
        ),
        ("disk I/O error", "could not write to its disk (disk I/O error)"),
        ("attempt to write a readonly database", "is read-only for this user; nothing was written"),
    ],
)
def test_a_full_disk_and_a_read_only_store_are_named_as_such(driver_message, words):
    import sqlite3

    from sqlalchemy import exc as sa_exc

    from calibctl.store.engine import make_engine, translate

    engine = make_engine("sqlite:///x.db")
    error = translate(sa_exc.OperationalError("INSERT", {}, sqlite3.OperationalError(driver_message)), engine)
    assert words in error.message and error.hint and error.exit_code == 2
