#!/usr/bin/env python3
"""Checks scoring.py's `score_honesty` on predictions of known quality (driven by tests/it/closed_loop.rs).

Four 480 × 270 images with a dozen rectangular buildings each (zoom_check.py's); every building is
predicted once, as its rectangle shifted by 0–20 px, so each mask's best IoU with the truth is known
to fall with the shift, and a few false blobs lie where no building is. Three results files score those
same masks: *honest* (the score falls with the shift, blobs lowest), *shuffled* (the honest scores in a
random order) and *constant* (0.9 everywhere). Prints one JSON object: the score report of each.
"""

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from zoom_check import H, W, print_reports, raster, rle  # noqa: E402


def write_dataset(root: Path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    images, anns, preds = [], [], []
    for i in range(1, 5):
        images.append({"id": i, "width": W, "height": H, "file_name": f"{i}.png"})
        for _ in range(12):
            x0, y0 = int(rng.integers(24, W - 100)), int(rng.integers(2, H - 60))
            box = (x0, y0, x0 + int(rng.integers(30, 70)), y0 + int(rng.integers(25, 50)))
            seg = rle(raster([box], 1.0))
            anns.append({"id": len(anns) + 1, "image_id": i, "category_id": 1, "iscrowd": 0, "segmentation": seg,
                         "area": int(box[2] - box[0]) * int(box[3] - box[1]), "bbox": [0.0, 0.0, 1.0, 1.0]})
            shift = int(rng.integers(0, 21))
            moved = (box[0] + shift, box[1], box[2] + shift, box[3])
            preds.append((i, rle(raster([moved], 1.0)), 0.98 - 0.02 * shift + float(rng.normal(0, 0.03))))
        for _ in range(3):  # false blobs in the left margin, where no building is
            y0 = int(rng.integers(2, H - 20))
            preds.append((i, rle(raster([(2, y0, 20, y0 + 15)], 1.0)), float(rng.uniform(0.3, 0.5))))
    (root / "instances.json").write_text(json.dumps(
        {"images": images, "annotations": anns, "categories": [{"id": 1, "name": "building"}]}))
    honest = [min(max(s, 0.0), 1.0) for _, _, s in preds]
    files = {"honest": honest, "shuffled": list(rng.permutation(honest)), "constant": [0.9] * len(preds)}
    for name, scores in files.items():
        results = [{"image_id": i, "category_id": 1, "segmentation": seg, "score": round(float(s), 5)}
                   for (i, seg, _), s in zip(preds, scores)]
        (root / f"results_{name}.json").write_text(json.dumps(results))


def main() -> int:
    return print_reports(write_dataset, ("honest", "shuffled", "constant"))


if __name__ == "__main__":
    sys.exit(main())
