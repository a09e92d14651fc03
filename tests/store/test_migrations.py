"""One migration history for both backends: single head, reversible with data, matching the models."""

from __future__ import annotations

import re

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import Column, Integer, MetaData, inspect, text
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.errors import DatabaseError, DatabaseOutOfDateError
from calibctl.store import migrate
from calibctl.store.engine import make_engine
from calibctl.store.models import Base
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.documents import capture_session

WHO = {"actor": "qa", "station": "st1", "reason": "solved"}
FIRST, SECOND, RIGS, HEAD = "0001_initial", "0002_image_retention", "0003_rigs", "0016_chain_health_reports"


def _diff(url: str, metadata: MetaData) -> list:
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            return compare_metadata(MigrationContext.configure(conn, opts={"compare_type": True}), metadata)
    finally:
        engine.dispose()


def _fill(url: str) -> dict:
    with Store.open(url) as store:
        board = store.add_board(measured_board())
        store.add_session(capture_session())
        art = store.add_artifact(calibration(), activate=True, **WHO)
        store.put_image(b"\x89PNG fake image bytes", retention_days=30)
        return {"board": board, "artifact": art, "session": store.get_session("0123456789ab")}


def test_one_head_and_date_prefixed_file_names():
    scripts = migrate.script_directory()
    assert scripts.get_heads() == [HEAD]
    assert migrate.known_revisions() == [
        FIRST,
        SECOND,
        RIGS,
        "0005_chains_signatures",
        "0006_check_events",
        "0007_chain_rigs_checks",
        "0008_chain_rig_definitions",
        "0009_chain_sessions_reads26",
        "0010_fleet_diff25",
        "0011_health_reports_health25",
        "0014_health_window_fleet25",
        "0015_checkpoints_fleet_ckpt",
        HEAD,
    ]
    for path in sorted(migrate.MIGRATIONS_DIR.joinpath("versions").glob("*.py")):
        assert re.fullmatch(r"\d{4}_\d{2}_\d{2}_\d{4}_[a-z0-9_]+\.py", path.name), path.name


def test_models_match_migrations(db_url: str):
    Store.open(db_url).close()  # created by running the migrations, never by create_all
    assert _diff(db_url, Base.metadata) == []
    # ... and the comparison does notice a difference when there is one.
    drifted = MetaData(naming_convention=Base.metadata.naming_convention)
    for table in Base.metadata.tables.values():
        table.to_metadata(drifted)
    drifted.tables["images"].append_column(Column("width_px", Integer, nullable=True))
    assert [d[0] for d in _diff(db_url, drifted)] == ["add_column"]


def test_upgrade_downgrade_upgrade_keeps_the_data(db_url: str):
    before = _fill(db_url)
    engine = make_engine(db_url)
    try:
        assert migrate.downgrade(engine, FIRST) == (HEAD, FIRST)
        assert "images" not in inspect(engine).get_table_names()
        assert migrate.upgrade(engine) == (FIRST, HEAD)
    finally:
        engine.dispose()
    with Store.open(db_url) as store:
        assert store.get_board("A17") == before["board"]
        assert store.get_artifact("CAM-0001") == before["artifact"]
        assert store.get_session("0123456789ab") == before["session"]
        assert store.verify().problems == []
        assert store.counts()["images"] == 0  # the images table is what 0002 adds; its rows went with it
    # the triggers of 0001 survived 0002's downgrade and upgrade
    engine = make_engine(db_url)
    try:
        with pytest.raises(Exception, match="calibration artifacts are immutable"), engine.begin() as conn:
            conn.execute(text("DELETE FROM calibration_artifacts"))
        assert migrate.downgrade(engine, "base") == (HEAD, None)
        assert set(inspect(engine).get_table_names()) <= {"alembic_version"}
        assert migrate.upgrade(engine) == (None, HEAD)
    finally:
        engine.dispose()
    with Store.open(db_url) as store:
        assert store.counts()["artifacts"] == 0


def test_an_older_database_is_refused_until_db_upgrade_migrates_it(db_url: str):
    before = _fill(db_url)
    engine = make_engine(db_url)
    migrate.downgrade(engine, FIRST)
    engine.dispose()
    with pytest.raises(DatabaseOutOfDateError) as info:
        Store.open(db_url)
    assert f"is at revision {FIRST}, this calibctl needs {HEAD}" in info.value.message
    assert "calibctl db upgrade" in (info.value.hint or "") and info.value.exit_code == 2

    runner = CliRunner()
    refused = runner.invoke(app, ["--db", db_url, "board", "list"])
    assert refused.exit_code == 2
    assert f"is at revision {FIRST}, this calibctl needs {HEAD}" in refused.stderr
    assert "Hint: run `calibctl db upgrade`" in refused.stderr

    current = runner.invoke(app, ["--db", db_url, "db", "current"])
    assert current.exit_code == 0 and "out of date; run `calibctl db upgrade`" in current.stdout

    upgraded = runner.invoke(app, ["--db", db_url, "db", "upgrade"])
    assert upgraded.exit_code == 0, upgraded.output
    assert f"upgraded {FIRST} -> {HEAD} (head)" in upgraded.stdout
    with Store.open(db_url) as store:
        assert store.get_artifact("CAM-0001") == before["artifact"]
        assert store.get_board("A17") == before["board"]


def test_a_database_from_a_newer_calibctl_is_refused(db_url: str):
    Store.open(db_url).close()
    engine = make_engine(db_url)
    with engine.begin() as conn:
        conn.execute(text("UPDATE alembic_version SET version_num = '0099_from_the_future'"))
    engine.dispose()
    with pytest.raises(
        DatabaseError, match="at revision 0099_from_the_future, which this calibctl does not know"
    ):
        Store.open(db_url)
    result = CliRunner().invoke(app, ["--db", db_url, "db", "upgrade"])
    assert result.exit_code == 2 and "which this calibctl does not know" in result.stderr
    assert "Hint: upgrade calibctl on this station" in result.stderr


def test_calibctl_tables_without_a_revision_are_refused(db_url: str):
    Store.open(db_url).close()
    engine = make_engine(db_url)
    with engine.begin() as conn:
        conn.execute(text("DROP TABLE alembic_version"))
    engine.dispose()
    with pytest.raises(DatabaseError, match="has calibctl tables .* but no schema revision"):
        Store.open(db_url)


def test_open_without_create_does_not_create(sqlite_url: str, tmp_path):
    from calibctl.errors import NotFoundError

    with pytest.raises(NotFoundError, match="there is no calibctl database at sqlite:///"):
        Store.open(sqlite_url, create=False)
    assert not (tmp_path / "calibctl.db").exists()
