"""COCO run-length encoding in numpy: masks to and from the compressed strings of pycocotools.

Training and prediction use this, so they run where pycocotools is not installed (a lent GPU machine);
scoring keeps pycocotools itself, the reference every COCO user trusts. Counts are column-major runs
starting with background; the string is pycocotools' `rleToString` form (5 bits a character, offset 48,
counts after the second stored as differences to the count two before).
"""

from __future__ import annotations

import numpy as np


def encode(mask: np.ndarray) -> dict:
    """`{"size": [h, w], "counts": str}` of a (h, w) mask."""
    h, w = mask.shape
    flat = np.ascontiguousarray(mask.astype(bool).T).ravel()
    edges = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    bounds = np.concatenate([[0], edges, [flat.size]])
    runs = np.diff(bounds).tolist()
    if flat.size and flat[0]:
        runs = [0] + runs
    return {"size": [int(h), int(w)], "counts": counts_to_string(runs)}


def decode(rle: dict) -> np.ndarray:
    """The (h, w) uint8 mask of an RLE with compressed (string) or uncompressed (list) counts."""
    h, w = rle["size"]
    counts = rle["counts"]
    runs = string_to_counts(counts) if isinstance(counts, (str, bytes)) else list(counts)
    if sum(runs) != h * w:
        raise ValueError(f"RLE counts sum to {sum(runs)}, not {h}×{w} = {h * w}")
    values = np.arange(len(runs)) % 2
    flat = np.repeat(values.astype(np.uint8), runs)
    return np.ascontiguousarray(flat.reshape(w, h).T)


def bbox(mask: np.ndarray) -> list[float]:
    """`[x, y, width, height]` of a mask's pixels (pycocotools' toBbox), zeros when empty."""
    ys, xs = np.nonzero(mask)
    if xs.size == 0:
        return [0.0, 0.0, 0.0, 0.0]
    return [float(xs.min()), float(ys.min()), float(xs.max() - xs.min() + 1), float(ys.max() - ys.min() + 1)]


def counts_to_string(runs: list[int]) -> str:
    out = []
    for i, run in enumerate(runs):
        x = run - runs[i - 2] if i > 2 else run
        more = True
        while more:
            c = x & 0x1F
            x >>= 5
            more = x != -1 if c & 0x10 else x != 0
            if more:
                c |= 0x20
            out.append(chr(c + 48))
    return "".join(out)


def string_to_counts(s: str | bytes) -> list[int]:
    if isinstance(s, bytes):
        s = s.decode("ascii")
    runs: list[int] = []
    p = 0
    while p < len(s):
        x = k = 0
        more = True
        while more:
            c = ord(s[p]) - 48
            x |= (c & 0x1F) << (5 * k)
            more = bool(c & 0x20)
            p += 1
            k += 1
            if not more and c & 0x10:
                x |= -1 << (5 * k)
        if len(runs) > 2:
            x += runs[-2]
        runs.append(x)
    return runs
