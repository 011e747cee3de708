#!/usr/bin/env python3
"""A data fix in one picture: the same frames' instance masks before and after, over the photo.

  fix_figure.py --rgb DIR --before DIR --after DIR --out FILE.png [--title TEXT] [--frames N]

DIRs hold `<frame>.png` (RGB photos; insgen 24-bit ID maps, id = R·65536 + G·256 + B). Picks the N
frames where the masks differ most; each row is photo | before | after, with the pixels that changed
outlined in yellow and counted (background pixels enclosed by one building: holes in its mask).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))

import scoring  # noqa: E402


def read_ids(path: Path) -> np.ndarray:
    rgb = np.asarray(Image.open(path).convert("RGB")).astype(np.uint32)
    return rgb[..., 0] << 16 | rgb[..., 1] << 8 | rgb[..., 2]


def holes(ids: np.ndarray) -> int:
    """Pixels of background regions (4-connected) that one building encloses: holes in its mask."""
    from scipy import ndimage

    bg, n = ndimage.label(ids == 0)
    if n == 0:
        return 0
    border = np.unique(np.concatenate([bg[0], bg[-1], bg[:, 0], bg[:, -1]]))
    total = 0
    for k, sl in enumerate(ndimage.find_objects(bg), start=1):
        if k in border:
            continue
        y0, y1 = max(sl[0].start - 1, 0), sl[0].stop + 1
        x0, x1 = max(sl[1].start - 1, 0), sl[1].stop + 1
        region = bg[y0:y1, x0:x1] == k
        ring = ndimage.binary_dilation(region) & ~region
        around = np.unique(ids[y0:y1, x0:x1][ring])
        if len(around) == 1 and around[0] != 0:
            total += int(region.sum())
    return total


def panel(ids: np.ndarray, rgb: np.ndarray, changed: np.ndarray) -> np.ndarray:
    masks = [ids == v for v in np.unique(ids) if v != 0]
    out = scoring.paint(masks, rgb)
    out[changed] = (255, 230, 0)
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rgb", type=Path, required=True)
    p.add_argument("--before", type=Path, required=True)
    p.add_argument("--after", type=Path, required=True)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--title", default="photo | before | after (changed pixels yellow)")
    p.add_argument("--frames", type=int, default=2)
    a = p.parse_args()
    rows = []
    names = sorted(f.name for f in a.after.glob("*.png") if (a.before / f.name).exists()
                   and (a.rgb / f.name).exists() and not f.name.startswith("preview"))
    if not names:
        sys.exit(f"fix_figure: no frame with a photo and both masks in {a.rgb}, {a.before}, {a.after}")
    diffs = []
    for n in names:
        b, f = read_ids(a.before / n), read_ids(a.after / n)
        diffs.append((int((b != f).sum()), n, b, f))
    diffs.sort(key=lambda t: (-t[0], t[1]))
    total_b = sum(holes(b) for _, _, b, _ in diffs)
    total_f = sum(holes(f) for _, _, _, f in diffs)
    for count, n, b, f in diffs[: a.frames]:
        rgb = np.asarray(Image.open(a.rgb / n).convert("RGB"))
        changed = b != f
        sep = np.full((rgb.shape[0], 4, 3), 255, np.uint8)
        row = np.concatenate([rgb, sep, panel(b, rgb, changed), sep, panel(f, rgb, changed)], axis=1)
        rows.append(scoring.caption(row, f"{n}: {count} px changed; hole pixels {holes(b)} -> {holes(f)}"))
    w = max(r.shape[1] for r in rows)
    head = scoring.caption(np.zeros((0, w, 3), np.uint8),
                           f"{a.title}; all {len(names)} frames: hole pixels {total_b} -> {total_f}")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = a.out.with_name(a.out.name + ".tmp.png")
    Image.fromarray(np.concatenate([head] + rows, axis=0)).save(tmp)
    tmp.replace(a.out)
    print(f"fix_figure: wrote {a.out} (hole pixels {total_b} -> {total_f} over {len(names)} frames)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
