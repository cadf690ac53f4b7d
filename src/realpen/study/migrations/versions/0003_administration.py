"""Study administration: pilot sessions, withdrawals; a plan row belongs to real sessions only.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-28

``sessions`` gains ``pilot`` (a session made to try the study out: it runs a plan row without
taking it) and ``withdrawn_at`` (when the participant withdrew consent). The unique plan row per
study becomes a partial unique index over the sessions that hold their row: neither a pilot nor
a withdrawn session does, so a pilot may run the row the next participant gets, and a withdrawn
participant's row can be given to a new one.

The tables are written out here so that this revision stays what it is when
:mod:`realpen.study.tables` changes.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None

HOLDS_ROW = "NOT pilot AND state <> 'withdrawn'"  # frozen copy of tables.HOLDS_PLAN_ROW


def upgrade() -> None:
    # SQLite cannot drop a constraint in place: batch mode copies sessions into a new table
    # (the caller has foreign keys off meanwhile, so trials and strokes keep their sessions).
    with op.batch_alter_table("sessions") as batch:
        batch.add_column(sa.Column("pilot", sa.Boolean, nullable=False,
                                   server_default=sa.false()))
        batch.add_column(sa.Column("withdrawn_at", sa.Text))
        batch.drop_constraint("uq_sessions_study_id_plan_index", type_="unique")
    op.create_index("sessions_by_plan_row", "sessions", ["study_id", "plan_index"], unique=True,
                    sqlite_where=sa.text(HOLDS_ROW), postgresql_where=sa.text(HOLDS_ROW))


def downgrade() -> None:
    # Revision 0002 has one session per plan row and knows neither pilots nor withdrawals: a
    # store that holds any cannot go back without losing what they mean, so it is refused.
    counts = op.get_bind().execute(sa.text(
        "SELECT SUM(CASE WHEN pilot THEN 1 ELSE 0 END), "
        "SUM(CASE WHEN state IN ('withdrawn', 'abandoned') THEN 1 ELSE 0 END) "
        "FROM sessions")).one()
    pilots, ended = int(counts[0] or 0), int(counts[1] or 0)
    if pilots or ended:
        raise RuntimeError(f"cannot downgrade below revision 0003: the store holds {pilots} "
                           f"pilot session(s) and {ended} withdrawn or abandoned session(s), "
                           f"which revision 0002 cannot hold; export and remove them first")
    op.drop_index("sessions_by_plan_row", table_name="sessions")
    with op.batch_alter_table("sessions") as batch:
        batch.create_unique_constraint("uq_sessions_study_id_plan_index",
                                       ["study_id", "plan_index"])
        batch.drop_column("withdrawn_at")
        batch.drop_column("pilot")
