"""alembic environment for calibctl: one migration stream for SQLite (batch mode) and PostgreSQL.

calibctl runs migrations programmatically (calibctl.store.migrate) and passes its own connection,
already inside a write transaction, in ``config.attributes["connection"]``. The alembic command line
works too: the URL comes from ``-x db=URL``, then CALIBCTL_DB, then ``sqlalchemy.url`` in alembic.ini.
"""

from __future__ import annotations

import os
from logging.config import fileConfig

from alembic import context
from sqlalchemy.engine import Connection

from calibctl.store import checks  # noqa: F401  (declares check_events on Base)
from calibctl.store.engine import WRITE_OPTION, make_engine, normalise_url
from calibctl.store.models import Base

config = context.config
target_metadata = Base.metadata


def _url() -> str:
    x_args = context.get_x_argument(as_dictionary=True)
    return normalise_url(
        x_args.get("db") or os.environ.get("CALIBCTL_DB") or config.get_main_option("sqlalchemy.url")
    )


def _run(connection: Connection) -> None:
    context.configure(
        connection=connection,
        target_metadata=target_metadata,
        render_as_batch=True,  # SQLite cannot ALTER most things; batch mode copies the table
        compare_type=True,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_offline() -> None:
    context.configure(url=_url(), target_metadata=target_metadata, literal_binds=True, render_as_batch=True)
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        _run(connection)  # the caller holds the transaction and the migration lock
        return
    if config.config_file_name is not None:
        fileConfig(config.config_file_name, disable_existing_loggers=False)
    engine = make_engine(_url())
    try:
        with engine.connect() as conn:
            conn.execution_options(**{WRITE_OPTION: True})
            with conn.begin():
                _run(conn)
    finally:
        engine.dispose()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
