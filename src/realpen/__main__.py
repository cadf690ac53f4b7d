"""``python -m realpen`` runs the ``realpen`` command."""

from realpen.cli import main

if __name__ == "__main__":  # importing it (as doctest collection does) runs nothing
    main()
