#!/usr/bin/env python3
"""Checks rle.py against pycocotools on seeded random masks (driven by tests/it/closed_loop.rs).

Prints one JSON object: how many masks were compared and how many differed in the compressed string,
the decoded mask (from either side's string) or the box.
"""

import json
import sys
from pathlib import Path

import numpy as np
from pycocotools import mask as mask_utils

sys.path.insert(0, str(Path(__file__).resolve().parent))

import rle  # noqa: E402


def main() -> int:
    rng = np.random.default_rng(int(sys.argv[1]) if len(sys.argv) > 1 else 0)
    masks, mismatches = 0, []
    for t in range(400):
        h, w = (int(v) for v in rng.integers(1, 48, 2))
        m = (rng.random((h, w)) < rng.random()).astype(np.uint8)
        if t % 5 == 0:
            m[:] = t % 2  # all background, all foreground
        ref = mask_utils.encode(np.asfortranarray(m))
        ours = rle.encode(m)
        ok = (ours["counts"] == ref["counts"].decode("ascii") and ours["size"] == [h, w]
              and np.array_equal(rle.decode(ours), m) and np.array_equal(rle.decode(ref), m)
              and np.array_equal(mask_utils.decode({"size": [h, w], "counts": ours["counts"].encode()}), m)
              and (m.sum() == 0 or rle.bbox(m) == [float(v) for v in mask_utils.toBbox(ref)]))
        masks += 1
        if not ok:
            mismatches.append(t)
    print(json.dumps({"masks": masks, "mismatches": mismatches}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
