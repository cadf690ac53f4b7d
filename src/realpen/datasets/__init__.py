"""Importers for public data formats: read other people's measurements without copying them.

- :mod:`realpen.datasets.hatt`: Penn Haptic Texture Toolkit (HaTT) ARMA texture models.
"""
