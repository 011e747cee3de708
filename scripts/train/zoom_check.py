#!/usr/bin/env python3
"""Checks scoring.py's `mask_zoom` on masks zoomed by known factors (driven by tests/it/closed_loop.rs).

Four 480 × 270 images with a principal point off the image centre, each with a dozen rectangular
buildings whose edges lie on pixel boundaries; the "predictions" are the same rectangles scaled by a
known zoom about the principal point and rasterised at pixel centres. Prints one JSON object: for each
zoom, the score report of `baseline.py score` (the measured `mask_zoom` should be the zoom).
"""

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from pycocotools import mask as mask_utils

sys.path.insert(0, str(Path(__file__).resolve().parent))

import scoring  # noqa: E402

W, H, CX, CY = 480, 270, 200.0, 120.0
ZOOMS = (0.99, 1.0, 1.003, 1.01)


def raster(boxes, zoom: float) -> np.ndarray:
    """The rectangles (x0, y0, x1, y1) scaled by `zoom` about (CX, CY), at pixel centres."""
    m = np.zeros((H, W), np.uint8)
    x, y = np.arange(W) + 0.5, np.arange(H) + 0.5
    for x0, y0, x1, y1 in boxes:
        zx = (CX + (x0 - CX) * zoom <= x) & (x < CX + (x1 - CX) * zoom)
        zy = (CY + (y0 - CY) * zoom <= y) & (y < CY + (y1 - CY) * zoom)
        m[np.ix_(zy, zx)] = 1
    return m


def rle(m: np.ndarray) -> dict:
    r = mask_utils.encode(np.asfortranarray(m))
    return {"size": r["size"], "counts": r["counts"].decode("ascii")}


def write_dataset(root: Path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    images, anns, results = [], [], {z: [] for z in ZOOMS}
    k = {"width_px": W, "height_px": H, "fx_px": 500.0, "fy_px": 500.0, "cx_px": CX, "cy_px": CY}
    for i in range(1, 5):
        images.append({"id": i, "width": W, "height": H, "file_name": f"{i}.png", "intrinsics": k})
        boxes = []
        for _ in range(12):
            x0, y0 = int(rng.integers(2, W - 80)), int(rng.integers(2, H - 60))
            boxes.append((x0, y0, x0 + int(rng.integers(20, 70)), y0 + int(rng.integers(15, 50))))
        for b in boxes:
            seg = rle(raster([b], 1.0))
            anns.append({"id": len(anns) + 1, "image_id": i, "category_id": 1, "iscrowd": 0, "segmentation": seg,
                         "area": int(mask_utils.area(seg)), "bbox": [float(v) for v in mask_utils.toBbox(seg)]})
        for z in ZOOMS:
            results[z].append({"image_id": i, "category_id": 1, "segmentation": rle(raster(boxes, z)), "score": 0.9})
    (root / "instances.json").write_text(json.dumps(
        {"images": images, "annotations": anns, "categories": [{"id": 1, "name": "building"}]}))
    for z, r in results.items():
        (root / f"results_{z}.json").write_text(json.dumps(r))


def print_reports(write, names) -> int:
    """Writes a dataset with `write(root, seed)` (seed: the first argument, else 0) into a temporary
    folder, scores its `results_<name>.json` files against its `instances.json` and prints the reports,
    one per name, as one JSON object (the check scripts' output)."""
    seed = int(sys.argv[1]) if len(sys.argv) > 1 else 0
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        write(root, seed)
        reports = {str(n): scoring.score(root / "instances.json", root / f"results_{n}.json") for n in names}
    for r in reports.values():
        r["coco"], r["results"] = "instances.json", "results.json"  # not the temporary folder's paths
    print(json.dumps(reports))
    return 0


def main() -> int:
    return print_reports(write_dataset, ZOOMS)


if __name__ == "__main__":
    sys.exit(main())
