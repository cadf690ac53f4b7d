"""``python -m realpen.cli`` runs the ``realpen`` command."""

from . import main

main()
