"""``python -m realpen.cli`` runs the ``realpen`` command."""

from realpen.cli import main

if __name__ == "__main__":  # importing (pytest --doctest-modules does) runs nothing
    main()
