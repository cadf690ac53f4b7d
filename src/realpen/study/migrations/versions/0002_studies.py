"""Studies: studies, participants, sessions, trials and answers; strokes know their trial.

Revision ID: 0002
Revises: 0001
Create Date: 2026-05-20

The result is :mod:`realpen.study.tables` as of this revision (tests/test_store_db.py compares
them); the tables are written out here so that this revision stays what it is when that module
changes.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "studies",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("name", sa.Text, nullable=False),
        sa.Column("version", sa.Text, nullable=False),
        sa.Column("design", sa.Text, nullable=False),
        sa.Column("created_at", sa.Text, nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_studies"),
        sa.UniqueConstraint("name", "version", name="uq_studies_name_version"),
    )
    op.create_table(
        "participants",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("study_id", sa.Integer, nullable=False),
        sa.Column("code", sa.Text, nullable=False),
        sa.Column("site", sa.Text, nullable=False, server_default=""),
        sa.Column("age", sa.Integer),
        sa.Column("gender", sa.Text),
        sa.Column("handedness", sa.Text),
        sa.Column("consent", sa.Boolean, nullable=False, server_default=sa.false()),
        sa.Column("created_at", sa.Text, nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_participants"),
        sa.ForeignKeyConstraint(["study_id"], ["studies.id"],
                                name="fk_participants_study_id_studies", ondelete="CASCADE"),
        sa.UniqueConstraint("study_id", "code", name="uq_participants_study_id_code"),
    )
    op.create_table(
        "sessions",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("study_id", sa.Integer, nullable=False),
        sa.Column("participant_id", sa.Integer, nullable=False),
        sa.Column("plan_index", sa.Integer, nullable=False),
        sa.Column("seed", sa.BigInteger, nullable=False),  # plan seeds go up to 2^63 - 1
        sa.Column("site", sa.Text, nullable=False, server_default=""),
        sa.Column("state", sa.Text, nullable=False, server_default="running"),
        sa.Column("started_at", sa.Text, nullable=False),
        sa.Column("finished_at", sa.Text),
        sa.PrimaryKeyConstraint("id", name="pk_sessions"),
        sa.ForeignKeyConstraint(["study_id"], ["studies.id"],
                                name="fk_sessions_study_id_studies", ondelete="CASCADE"),
        sa.ForeignKeyConstraint(["participant_id"], ["participants.id"],
                                name="fk_sessions_participant_id_participants", ondelete="CASCADE"),
        sa.UniqueConstraint("study_id", "participant_id",
                            name="uq_sessions_study_id_participant_id"),
        sa.UniqueConstraint("study_id", "plan_index", name="uq_sessions_study_id_plan_index"),
    )
    op.create_table(
        "trials",
        sa.Column("session_id", sa.Integer, nullable=False),
        sa.Column("n", sa.Integer, nullable=False),
        sa.Column("block", sa.Text, nullable=False),
        sa.Column("block_index", sa.Integer, nullable=False),
        sa.Column("phase", sa.Text, nullable=False),
        sa.Column("condition", sa.Text, nullable=False, server_default=""),
        sa.Column("modality", sa.Text, nullable=False, server_default=""),
        sa.Column("pen", sa.Text, nullable=False, server_default=""),
        sa.Column("ink", sa.Text, nullable=False, server_default="visible"),
        sa.Column("repetition", sa.Integer, nullable=False, server_default=sa.text("0")),
        sa.Column("plan", sa.Text, nullable=False),
        sa.Column("answered_at", sa.Text),
        sa.Column("rt_ms", sa.Float),
        sa.PrimaryKeyConstraint("session_id", "n", name="pk_trials"),
        sa.ForeignKeyConstraint(["session_id"], ["sessions.id"],
                                name="fk_trials_session_id_sessions", ondelete="CASCADE"),
    )
    op.create_table(
        "answers",
        sa.Column("session_id", sa.Integer, nullable=False),
        sa.Column("n", sa.Integer, nullable=False),
        sa.Column("question", sa.Text, nullable=False),
        sa.Column("answer", sa.Text, nullable=False),
        sa.Column("correct", sa.Boolean),
        sa.PrimaryKeyConstraint("session_id", "n", "question", name="pk_answers"),
        sa.ForeignKeyConstraint(["session_id", "n"], ["trials.session_id", "trials.n"],
                                name="fk_answers_trial", ondelete="CASCADE"),
    )
    # SQLite cannot add a foreign key to a table: batch mode copies strokes into a new table
    # (the caller has foreign keys off meanwhile, so samples keep their strokes).
    with op.batch_alter_table("strokes", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("study_session", sa.Integer))
        batch.add_column(sa.Column("trial", sa.Integer))
        batch.create_foreign_key("fk_strokes_study_session_sessions", "sessions",
                                 ["study_session"], ["id"], ondelete="SET NULL")
    op.create_index("strokes_by_trial", "strokes", ["study_session", "trial"])


def downgrade() -> None:
    op.drop_index("strokes_by_trial", table_name="strokes")
    with op.batch_alter_table("strokes", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.drop_constraint("fk_strokes_study_session_sessions", type_="foreignkey")
        batch.drop_column("trial")
        batch.drop_column("study_session")
    for table in ("answers", "trials", "sessions", "participants", "studies"):
        op.drop_table(table)
