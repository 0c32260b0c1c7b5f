"""Compose the README's overview image from a reproduction's run directory.

Usage: python scripts/make_overview.py [RUN_DIR] [OUT]
(defaults: the newest finished run among runs/reproduce, runs/reproduce-2, ... and
docs/img/overview.png). Puts the corridor's final-policy circuit
(``corridor/map.png``) beside the driving experiment's Figure 8
(``driving/fig8_lanes_collisions.png``), both scaled to the same height.
"""

from __future__ import annotations

import sys
from pathlib import Path

from PIL import Image

from torchcbl.cli import latest_run


def main(run_dir: Path, out: Path) -> None:
    parts = [run_dir / "corridor" / "map.png", run_dir / "driving" / "fig8_lanes_collisions.png"]
    missing = [str(p) for p in parts if not p.is_file()]
    if missing:
        sys.exit(f"make_overview: missing {', '.join(missing)}; run `bash scripts/reproduce.sh`")
    images = [Image.open(p).convert("RGB") for p in parts]
    height = max(im.height for im in images)
    images = [im.resize((round(im.width * height / im.height), height)) for im in images]
    canvas = Image.new("RGB", (sum(im.width for im in images), height), "white")
    x = 0
    for im in images:
        canvas.paste(im, (x, 0))
        x += im.width
    out.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(out, optimize=True)
    print(f"wrote {out} ({canvas.width}x{canvas.height})")


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", nargs="?", type=Path, help="default: the newest finished run")
    ap.add_argument("out", nargs="?", type=Path, default=Path("docs/img/overview.png"))
    ns = ap.parse_args()
    main(ns.run_dir or latest_run(), ns.out)
