"""Regenerate the bundled pen profiles (pencil, ballpoint, marker) from the pen model.

The model (``realpen.pens.model``) writes a vibration recording and a friction-sound recording
per pen; those go through exactly the pipeline of ``realpen profile build``. The model is
seeded, so running this again on the same machine gives byte-identical bundles (on another, equal
within the tolerances of ``tests/test_profile.py``, with the same canonical profile version).

Usage: python scripts/make_bundled_pens.py [OUT_DIR]   (default: src/realpen/pens/bundled)
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from realpen.pens import BUNDLE_ACTUATOR, BUNDLED_PENS, bundled_dir
from realpen.pens.build import build_modelled_pen
from realpen.profile.bundle import save_profile


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else bundled_dir()
    with tempfile.TemporaryDirectory() as scratch:
        for name in BUNDLED_PENS:
            profile = build_modelled_pen(name, Path(scratch), BUNDLE_ACTUATOR)
            save_profile(profile, out / name)
            print(f"wrote {out / name}: {profile.summary()}")


if __name__ == "__main__":
    main()
