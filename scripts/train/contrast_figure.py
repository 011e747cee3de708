#!/usr/bin/env python3
"""The neighbour-contrast fix in one picture: the same frames rendered without and with it.

  contrast_figure.py --before DIR --after DIR --masks DIR --out FILE.{png,jpg} [--title TEXT] [--frames N]

--before and --after hold RGB photos `<frame>.png` of the same poses (render-rgb
--no-neighbour-contrast, and the default); --masks the frames' insgen 24-bit ID maps (id = R·65536 +
G·256 + B). Each row: photo before | photo after | the after photo with the boundaries between touching
buildings in yellow; captions give the colour contrast across those boundaries and across building /
background boundaries, as `insgen stats` defines it (|ΔR| + |ΔG| + |ΔB| over 3 between 4-neighbours, in
0–255 levels). Picks the N frames with the longest touching boundary.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))

import scoring  # noqa: E402
from fix_figure import read_ids  # noqa: E402


# The 4-neighbour pairs as (index a, index b) slices: horizontal, then vertical.
PAIRS = [((slice(None), slice(0, -1)), (slice(None), slice(1, None))),
         ((slice(0, -1), slice(None)), (slice(1, None), slice(None)))]


def contrast(ids: np.ndarray, rgb: np.ndarray):
    """(touching sum, touching pairs, background sum, background pairs, touching-boundary mask)."""
    rgb = rgb.astype(np.int32)
    sums = [0, 0, 0, 0]
    edge = np.zeros(ids.shape, bool)
    for a, b in PAIRS:
        ia, ib = ids[a], ids[b]
        diff = np.abs(rgb[a] - rgb[b]).sum(axis=-1)
        touching = (ia != 0) & (ib != 0) & (ia != ib)
        background = (ia == 0) != (ib == 0)
        sums[0] += int(diff[touching].sum())
        sums[1] += int(touching.sum())
        sums[2] += int(diff[background].sum())
        sums[3] += int(background.sum())
        edge[a] |= touching
        edge[b] |= touching
    return sums[0], sums[1], sums[2], sums[3], edge


def levels(total: int, count: int) -> float:
    return total / count / 3.0 if count else 0.0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--before", type=Path, required=True)
    p.add_argument("--after", type=Path, required=True)
    p.add_argument("--masks", type=Path, required=True)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--title", default="photo without neighbour contrast | with | touching boundaries")
    p.add_argument("--frames", type=int, default=2)
    a = p.parse_args()
    names = sorted(f.name for f in a.after.glob("*.png")
                   if (a.before / f.name).exists() and (a.masks / f.name).exists()
                   and not f.name.startswith(("preview", "side_by_side")))
    if not names:
        sys.exit(f"contrast_figure: no frame with both photos and an ID map in {a.before}, {a.after}, {a.masks}")
    frames, totals = [], np.zeros((2, 4), np.int64)
    for n in names:
        ids = read_ids(a.masks / n)
        before = np.asarray(Image.open(a.before / n).convert("RGB"))
        after = np.asarray(Image.open(a.after / n).convert("RGB"))
        cb, ca = contrast(ids, before), contrast(ids, after)
        totals[0] += cb[:4]
        totals[1] += ca[:4]
        frames.append((-cb[1], n, before, after, ca[4], cb, ca))
    frames.sort(key=lambda t: (t[0], t[1]))
    rows = []
    for _, n, before, after, edge, cb, ca in frames[: a.frames]:
        marked = after.copy()
        marked[edge] = (255, 230, 0)
        sep = np.full((after.shape[0], 4, 3), 255, np.uint8)
        row = np.concatenate([before, sep, after, sep, marked], axis=1)
        rows.append(scoring.caption(row, (
            f"{n}: {cb[1]} touching px; contrast touching {levels(cb[0], cb[1]):.1f} -> {levels(ca[0], ca[1]):.1f}, "
            f"background {levels(cb[2], cb[3]):.1f} -> {levels(ca[2], ca[3]):.1f} levels")))
    (tb, nb, bb, mb), (ta, na, ba, ma) = totals.tolist()
    ratio_b, ratio_a = levels(tb, nb) / max(levels(bb, mb), 1e-9), levels(ta, na) / max(levels(ba, ma), 1e-9)
    w = max(r.shape[1] for r in rows)
    head = scoring.caption(np.zeros((0, w, 3), np.uint8), (
        f"{a.title}; {len(names)} frames: contrast touching / background {levels(tb, nb):.1f} / {levels(bb, mb):.1f} "
        f"(ratio {ratio_b:.2f}) -> {levels(ta, na):.1f} / {levels(ba, ma):.1f} (ratio {ratio_a:.2f})"))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = a.out.with_name(a.out.stem + ".tmp" + a.out.suffix)
    Image.fromarray(np.concatenate([head] + rows, axis=0)).save(tmp, quality=88)
    tmp.replace(a.out)
    print(f"contrast_figure: wrote {a.out} (touching / background contrast ratio {ratio_b:.2f} -> {ratio_a:.2f} "
          f"over {len(names)} frames)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
