"""``python -m realpen`` runs the ``realpen`` command."""

from realpen.cli import main

main()
