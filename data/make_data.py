"""Write the small data slamrel makes itself into ``data/`` (see ``data/README.md``).

Everything here is a pure function of fixed seeds: running the script again gives the same
bytes (``tests/test_data.py`` checks it). Run from the project root::

    python data/make_data.py              # rewrite data/example and data/sim-bundle
    python data/make_data.py -o /tmp/d    # write them elsewhere (e.g. to compare)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # this checkout's code, also when not installed

from slamrel.cli import main as slamrel  # noqa: E402
from slamrel.formats.bundle import write_bundle  # noqa: E402
from slamrel.simulation.bundles import simulate_bundle  # noqa: E402

EXAMPLE_SEED = 0
BUNDLE_SEED = 1
# A short drive (10 s at 1 m/s, measurements at 2 Hz) through 8 landmarks, with a SLAM-like
# map: the true landmarks moved by an error drawn from the stated joint covariance.
BUNDLE_OPTIONS = {"steps": 100, "landmarks": 8, "map_sigma": (0.02, 0.05), "map_covariance": True}


def make(out: Path) -> list[Path]:
    """Write ``example/`` and ``sim-bundle/`` into ``out``; return the folders written."""
    example, bundle = out / "example", out / "sim-bundle"
    rc = slamrel(["example", "-o", str(example), "--seed", str(EXAMPLE_SEED), "--force", "-q"])
    if rc != 0:
        raise SystemExit(rc)
    write_bundle(bundle, simulate_bundle(BUNDLE_SEED, **BUNDLE_OPTIONS), force=True)
    return [example, bundle]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", type=Path, default=HERE, metavar="DIR")
    args = ap.parse_args(argv)
    for folder in make(args.output):
        print(f"wrote {folder}")


if __name__ == "__main__":
    main()
