"""The store's schema revisions, oldest first: ``0001`` strokes and samples, ``0002`` studies,
``0003`` study administration (pilot sessions, withdrawals)."""
