"""Alembic migrations of the store (run by :func:`realpen.study.db.open_database`)."""
