"""The store's schema revisions, oldest first: ``0001`` strokes and samples, ``0002`` studies."""
