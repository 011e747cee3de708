"""PSNR and SSIM of rendered frames against reference crops (the RGB quality bench, scripts/bench_rgb.sh).

    .venv/bin/python scripts/bench/rgb_metrics.py REFERENCE.png IMAGE.png [IMAGE.png ...]

REFERENCE.png is the centred crop written by rgb_reference.py; each IMAGE.png is a full frame (or a crop
of the same size), from which the same centred window is cut. Prints one JSON object per image:
{"image": ..., "psnr_db": ..., "ssim": ...}.

- PSNR over the 8-bit sRGB values of all three channels, peak 255: 10 log10(255^2 / MSE).
- SSIM (Wang et al. 2004, "Image quality assessment: from error visibility to structural similarity",
  IEEE TIP 13(4)) on the luminance Y = 0.299 R + 0.587 G + 0.114 B (ITU-R BT.601) of the 8-bit values,
  Gaussian window 11x11 with sigma 1.5, K1 = 0.01, K2 = 0.03, L = 255, mean over the 'valid' window
  positions: the parameters of the paper and of scikit-image's `structural_similarity(...,
  gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=255)`.
"""

import json
import sys

import numpy as np
from PIL import Image


def load(path):
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)


def centre_crop(img, h, w):
    H, W = img.shape[:2]
    y0, x0 = (H - h) // 2, (W - w) // 2
    return img[y0:y0 + h, x0:x0 + w]


def psnr_db(a, b):
    mse = np.mean((a - b) ** 2)
    return float("inf") if mse == 0 else float(10.0 * np.log10(255.0 ** 2 / mse))


def gaussian_kernel(size=11, sigma=1.5):
    x = np.arange(size) - (size - 1) / 2.0
    g = np.exp(-(x ** 2) / (2.0 * sigma ** 2))
    return g / g.sum()


def filter_valid(img, g):
    """Separable correlation with the 1-D kernel g along both axes, 'valid' positions only."""
    n = len(g)
    rows = sum(g[k] * img[:, k:img.shape[1] - n + 1 + k] for k in range(n))
    return sum(g[k] * rows[k:rows.shape[0] - n + 1 + k, :] for k in range(n))


def ssim(a, b):
    ya = a @ np.array([0.299, 0.587, 0.114])
    yb = b @ np.array([0.299, 0.587, 0.114])
    g = gaussian_kernel()
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    mu_a, mu_b = filter_valid(ya, g), filter_valid(yb, g)
    s_aa = filter_valid(ya * ya, g) - mu_a ** 2
    s_bb = filter_valid(yb * yb, g) - mu_b ** 2
    s_ab = filter_valid(ya * yb, g) - mu_a * mu_b
    m = ((2 * mu_a * mu_b + c1) * (2 * s_ab + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (s_aa + s_bb + c2))
    return float(m.mean())


def main(argv):
    ref = load(argv[1])
    h, w = ref.shape[:2]
    for path in argv[2:]:
        img = centre_crop(load(path), h, w)
        print(json.dumps({"image": path, "psnr_db": round(psnr_db(ref, img), 2), "ssim": round(ssim(ref, img), 4)}))


if __name__ == "__main__":
    main(sys.argv)
