"""calibctl touches only what is its own: `--db` on another application's database is refused naming it
and leaves it byte-identical; `rig export --format bundle --force` replaces only the files the previous
manifest lists, and refuses a folder that holds anything else (a user's notes, a subfolder, a symlink)."""

from __future__ import annotations

import hashlib
import sqlite3

import pytest
import sqlalchemy

from tests.cli.rig.test_rig_export_cli import db, invoke, rig2, solved  # noqa: F401 - fixtures


def _text(r):
    return " ".join(r.output.split())


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize("journal", ["delete", "wal"])
def test_another_applications_sqlite_file_is_refused_and_left_byte_identical(tmp_path, journal):
    path = tmp_path / "app.db"
    with sqlite3.connect(path) as conn:
        conn.execute(f"PRAGMA journal_mode = {journal}")
        conn.execute("CREATE TABLE notes (body TEXT)")
        conn.execute("INSERT INTO notes VALUES ('mine')")
    conn.close()
    before = _digest(path)
    for args in (("history", "CAM0"), ("db", "upgrade")):
        r = invoke(f"sqlite:///{path}", *args)
        assert r.exit_code == 2, r.output
        assert f"{path} is not a calibctl store" in _text(r) and "(notes)" in _text(r)
    assert _digest(path) == before
    with sqlite3.connect(path) as conn:
        assert [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")] == [
            "notes"
        ]
    conn.close()


def test_a_file_that_is_no_database_is_refused_and_left_alone(tmp_path):
    path = tmp_path / "notes.db"
    path.write_text("my notes\n")
    r = invoke(f"sqlite:///{path}", "db", "upgrade")
    assert r.exit_code == 2 and f"{path} is not a SQLite database" in _text(r)
    assert path.read_text() == "my notes\n"


@pytest.mark.postgres
def test_another_applications_postgresql_database_is_refused(pg_url):
    engine = sqlalchemy.create_engine(pg_url.replace("postgresql://", "postgresql+psycopg://", 1))
    with engine.begin() as conn:
        conn.execute(sqlalchemy.text("CREATE TABLE orders (id INTEGER)"))
    r = invoke(pg_url, "db", "upgrade")
    assert r.exit_code == 2 and "is not a calibctl store" in _text(r) and "(orders)" in _text(r)
    with engine.connect() as conn:
        tables = sqlalchemy.inspect(conn).get_table_names()
    engine.dispose()
    assert tables == ["orders"]


@pytest.mark.parametrize("intruder", ["notes.txt", "sub/", "link"])
def test_bundle_force_refuses_a_folder_holding_anything_the_manifest_does_not_list(db, tmp_path, intruder):
    out = tmp_path / "bundle"
    assert invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out)).exit_code == 0
    outside = tmp_path / "outside.txt"
    outside.write_text("theirs")
    if intruder == "notes.txt":
        (out / "notes.txt").write_text("mine")
    elif intruder == "sub/":
        (out / "sub").mkdir()
        (out / "sub" / "x.txt").write_text("mine")
    else:
        (out / "link").symlink_to(outside)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and not p.is_symlink()}
    r = invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out), "--force")
    assert r.exit_code == 2, r.output
    assert f"{out} holds {intruder.rstrip('/')}" in _text(r) and "move " in _text(r)
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and not p.is_symlink()} == before
    assert outside.read_text() == "theirs"


def test_bundle_force_never_replaces_a_listed_file_that_became_a_symlink(db, tmp_path):
    out = tmp_path / "bundle"
    assert invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out)).exit_code == 0
    outside = tmp_path / "outside.yaml"
    outside.write_text("theirs")
    (out / "tf_static.yaml").unlink()
    (out / "tf_static.yaml").symlink_to(outside)
    r = invoke(db, "rig", "export", "R1", "--format", "bundle", "-o", str(out), "--force")
    assert r.exit_code == 2 and "tf_static.yaml (a symlink)" in _text(r)
    assert (out / "tf_static.yaml").is_symlink() and outside.read_text() == "theirs"
    r = invoke(db, "lint", str(out / "manifest.json"))
    assert r.exit_code == 1 and "is a symlink" in _text(r)


def test_another_alembic_applications_database_is_refused_as_foreign(tmp_path):
    path = tmp_path / "app.db"
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE alembic_version (version_num VARCHAR(32) NOT NULL)")
        conn.execute("INSERT INTO alembic_version VALUES ('1a2b3c4d5e6f')")
        conn.execute("CREATE TABLE orders (id INTEGER)")
    conn.close()
    before = _digest(path)
    r = invoke(f"sqlite:///{path}", "db", "upgrade")
    assert r.exit_code == 2 and f"{path} is not a calibctl store" in _text(r) and "(orders)" in _text(r)
    assert _digest(path) == before
