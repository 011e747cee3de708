"""From model outputs to instances, and instances to a COCO results file.

The bottom-up decoding: building pixels are where interior + rim probability exceeds `fg_threshold`;
seeds are the connected cores (of at least a quarter of `min_area_px`) where the predicted distance to
the instance edge, smoothed over a pixel, exceeds `seed_threshold` and the interior wins; a watershed of the negated distance map floods the building
pixels from the seeds, so touching buildings split along the predicted rim valleys. Building components
without a seed become one instance each. An instance's score is the geometric mean of its pixels'
mean building probability and its core's mean interior probability (0–1, higher = more confident).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from skimage.segmentation import watershed

import rle


def decode_unet(probs: np.ndarray, dist: np.ndarray, fg_threshold: float = 0.5, seed_threshold: float = 0.35,
                min_area_px: int = 16) -> list[tuple[np.ndarray, float]]:
    """Instances from class probabilities `probs` (3, h, w) and distance `dist` (h, w), both 0–1.

    Returns `(mask, score)` pairs, masks (h, w) bool, ordered by score (highest first).
    """
    fg_prob = probs[1] + probs[2]
    fg = fg_prob > fg_threshold
    # A lightly smoothed distance map, and seeds of at least a quarter of the smallest instance: an
    # undertrained model's noisy distance peaks would otherwise each start an instance.
    dist = ndimage.gaussian_filter(dist, sigma=1.0)
    seeds = fg & (dist > seed_threshold) & (probs[1] > probs[2])
    markers, n = ndimage.label(seeds)
    if n:
        seed_px = np.bincount(markers.ravel(), minlength=n + 1)
        keep = seed_px >= max(1, min_area_px // 4)
        keep[0] = False
        markers, n = ndimage.label(keep[markers])
    comps, n_comp = ndimage.label(fg)
    if n_comp:
        # A building component with no seed (small or thin) is an instance of its own.
        seeded = np.zeros(n_comp + 1, bool)
        seeded[np.unique(comps[markers > 0])] = True
        lone = ~seeded[comps] & fg
        if lone.any():
            extra, n_extra = ndimage.label(lone)
            markers[lone] = extra[lone] + n
            n += n_extra
    if n == 0:
        return []
    labels = watershed(-dist, markers, mask=fg)
    out = []
    idx = np.arange(1, n + 1)
    areas = ndimage.sum(np.ones_like(labels), labels, idx)
    fg_mean = ndimage.mean(fg_prob, labels, idx)
    core_mean = ndimage.mean(probs[1], markers, idx)
    for k in range(n):
        if areas[k] < min_area_px:
            continue
        core = core_mean[k] if np.isfinite(core_mean[k]) else fg_mean[k]
        score = float(np.sqrt(fg_mean[k] * core))
        out.append((labels == k + 1, score))
    out.sort(key=lambda t: -t[1])
    return out


def result_entries(image_id: int, instances: list[tuple[np.ndarray, float]], category_id: int = 1) -> list[dict]:
    """COCO results entries (compressed RLE, bbox, score) for one image."""
    entries = []
    for mask, score in instances:
        entries.append({
            "image_id": int(image_id),
            "category_id": int(category_id),
            "segmentation": rle.encode(mask),
            "bbox": rle.bbox(mask),
            "score": round(float(score), 5),
        })
    return entries


def instance_map(instances: list[tuple[np.ndarray, float]], shape: tuple[int, int],
                 min_score: float = 0.0) -> np.ndarray:
    """Paints instances (lowest score first, so confident ones win overlaps) into an int32 label map."""
    out = np.zeros(shape, np.int32)
    for k, (mask, score) in sorted(enumerate(instances, start=1), key=lambda t: t[1][1]):
        if score >= min_score:
            out[mask] = k
    return out
