"""Pack MakeHuman's CC0 bodies, garments, hair, rig and poses into sitl/render/bodies/data/bodies.npz.

Run once when the asset selection changes: ``.venv/bin/python -m scripts.pack_bodies [--assets DIR]``. The pack is
in the repository; nothing reads the asset tree at run time.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from sitl.assets.makehuman_pack import pack
from sitl.render.bodies.library import CELL_DM, PACK_PATH

DEFAULT_ASSETS = Path(__file__).resolve().parents[2] / "shared" / "assets" / "makehuman"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--assets", type=Path, default=DEFAULT_ASSETS, help="the makehuman asset tree")
    parser.add_argument("--out", type=Path, default=PACK_PATH)
    parser.add_argument("--cell-dm", type=float, default=CELL_DM, help="decimation cell, decimetres")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = pack(args.assets, args.out, args.cell_dm)
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
