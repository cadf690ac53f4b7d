"""The stroke store as it was before Alembic (SQLite ``user_version`` 2): strokes and samples.

Revision ID: 0001
Revises:
Create Date: 2026-05-20

An SQLite store of version 1 or 2 is stamped with this revision (after the v1→v2 upgrade), so
its tables are exactly these: keep them frozen.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects import sqlite

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

# REAL on SQLite, as the stroke store always declared it; double precision on PostgreSQL.
REAL = sa.Float().with_variant(sqlite.REAL(), "sqlite")
SAMPLE_FIELDS = ("t", "x", "y", "pressure", "tilt_x", "tilt_y", "speed")  # frozen copy


def upgrade() -> None:
    op.create_table(
        "strokes",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("session", sa.Text, nullable=False),
        sa.Column("page_stroke", sa.Integer, nullable=False),
        sa.Column("pen", sa.Text, nullable=False),
        sa.Column("profile_version", sa.Text, nullable=False),
        sa.Column("modality", sa.Text, nullable=False),
        sa.Column("ink", sa.Text, nullable=False),
        sa.Column("pointer_type", sa.Text, nullable=False),
        sa.Column("px_per_mm", REAL, nullable=False),
        sa.Column("calibrated", sa.Integer, nullable=False),
        sa.Column("page_t0", REAL, nullable=False),
        sa.Column("started_at", sa.Text, nullable=False),
        sa.Column("ended_at", sa.Text),
        sa.Column("end_reason", sa.Text),
        sa.Column("sample_count", sa.Integer, nullable=False, server_default=sa.text("0")),
        sa.Column("page", sa.Text),
        sa.PrimaryKeyConstraint("id", name="pk_strokes"),
        sqlite_autoincrement=True,  # ids are never reused, even after a delete
    )
    op.create_table(
        "samples",
        sa.Column("stroke_id", sa.Integer, nullable=False),
        sa.Column("seq", sa.Integer, nullable=False),
        *(sa.Column(name, REAL, nullable=False) for name in SAMPLE_FIELDS),
        sa.PrimaryKeyConstraint("stroke_id", "seq", name="pk_samples"),
        sa.ForeignKeyConstraint(["stroke_id"], ["strokes.id"], name="fk_samples_stroke_id_strokes",
                                ondelete="CASCADE"),
        sqlite_with_rowid=False,
    )
    op.create_index("strokes_by_page", "strokes", ["page", "page_stroke"], unique=True)


def downgrade() -> None:
    op.drop_index("strokes_by_page", table_name="strokes")
    op.drop_table("samples")
    op.drop_table("strokes")
