"""Alembic's environment for RealPen's store: run programmatically by
:func:`realpen.study.db.open_database`, on the connection (and inside the transaction) it passes
in ``config.attributes["connection"]``; no ``alembic.ini`` is needed.

A new revision is written the usual way, with a small ``alembic.ini`` of your own whose
``script_location`` is this folder; keep each revision frozen (its own table definitions, not
:mod:`realpen.study.tables`), and run it on SQLite and PostgreSQL (tests/test_store_db.py).
"""

from __future__ import annotations

from alembic import context

from realpen.study.tables import metadata


def run_migrations() -> None:
    connection = context.config.attributes.get("connection")
    if connection is None:
        raise RuntimeError("RealPen's migrations run on a connection given in "
                           "config.attributes['connection'] (see realpen.study.db)")
    context.configure(
        connection=connection,
        target_metadata=metadata,
        # SQLite alters little in place: a changed table is copied into a new one.
        render_as_batch=connection.dialect.name == "sqlite",
    )
    with context.begin_transaction():
        context.run_migrations()


# Only under Alembic: importing this file elsewhere (a doctest collector) does nothing.
if hasattr(context, "config"):
    run_migrations()
