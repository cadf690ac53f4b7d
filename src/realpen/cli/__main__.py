"""``python -m realpen.cli`` runs the ``realpen`` command."""

from realpen.cli import main

main()
