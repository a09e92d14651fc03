"""The schema check reads revision ids without alembic; it must agree with alembic itself."""

from __future__ import annotations

import pytest
from sqlalchemy import text

from calibctl.errors import DatabaseError
from calibctl.store import migrate
from calibctl.store.engine import make_engine


def test_head_and_known_revisions_match_alembics_script_directory():
    scripts = migrate.script_directory()
    assert migrate.head_revision() == scripts.get_current_head()
    assert migrate.known_revisions() == [s.revision for s in reversed(list(scripts.walk_revisions()))]


def test_the_revision_lines_of_alembics_own_template_are_read(tmp_path, monkeypatch):
    versions = tmp_path / "versions"
    versions.mkdir()
    (versions / "a.py").write_text(
        '"""first\n\nRevision ID: r1\nRevises:\n"""\nrevision: str = "r1"\n'
        "down_revision: str | Sequence[str] | None = None\n",
        encoding="utf-8",
    )
    (versions / "b.py").write_text("revision = 'r2'\ndown_revision = ('r1',)\n", encoding="utf-8")
    monkeypatch.setattr(migrate, "MIGRATIONS_DIR", tmp_path)
    migrate._revision_graph.cache_clear()
    try:
        assert migrate.head_revision() == "r2" and migrate.known_revisions() == ["r1", "r2"]
    finally:
        migrate._revision_graph.cache_clear()


def test_a_store_at_two_revisions_is_refused(sqlite_url):
    migrate.upgrade_url(sqlite_url)
    engine = make_engine(sqlite_url)
    try:
        with engine.begin() as conn:
            conn.execute(text("INSERT INTO alembic_version (version_num) VALUES ('0001_initial')"))
        with pytest.raises(DatabaseError, match="several schema revisions at once") as exc:
            migrate.read_state(engine)
        assert migrate.head_revision() in exc.value.message and "0001_initial" in exc.value.message
        assert exc.value.exit_code == 2 and "restore it from a backup" in exc.value.hint
    finally:
        engine.dispose()
