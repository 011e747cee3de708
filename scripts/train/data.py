"""Reading an insgen COCO export into training frames, and the per-pixel targets of the bottom-up model.

A frame is one `images[]` entry of an `instances_<split>.json`: the RGB photo (`file_name`, relative to
`info.image_root`, itself relative to the JSON's folder) and an instance map painted from the
annotations' masks (RLE, or polygons rasterised by pycocotools), so any COCO instance file works, not
only insgen's. Pixels to leave out of the loss: `iscrowd` annotations and insgen's `ignore_file` (255 where a
photogrammetry tileset hides a LoD building).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image
from scipy import ndimage

import rle

IGNORE = 255


class DataError(Exception):
    """A dataset problem, with the file it is about."""


@dataclass
class Frame:
    """One image with its instances, at the resolution the model sees."""

    image_id: int
    file_name: str
    area_name: str
    width_px: int  # native size (the results file's masks have it)
    height_px: int
    rgb: np.ndarray  # (h, w, 3) uint8 at model resolution
    instances: np.ndarray  # (h, w) int32, 0 = background, k = k-th annotation
    ignore: np.ndarray  # (h, w) bool


def load_split(coco_json: Path, areas: list[str] | None = None, scale: float = 1.0,
               limit: int | None = None) -> tuple[dict, list[Frame]]:
    """Reads one instances file and its frames, optionally only `areas`, resized by `scale`."""
    try:
        data = json.loads(coco_json.read_text())
    except FileNotFoundError as e:
        raise DataError(f"{coco_json}: no such file (run `insgen export-coco`)") from e
    except json.JSONDecodeError as e:
        raise DataError(f"{coco_json}: not JSON: {e}") from e
    if not isinstance(data, dict) or "images" not in data or "annotations" not in data:
        raise DataError(f"{coco_json}: not a COCO instances file (no images/annotations)")
    if data.get("info", {}).get("images_missing"):
        raise DataError(f"{coco_json}: a label-only export (images not rendered; run `insgen render-rgb` "
                        "and export again without --label-only)")
    root = coco_json.parent / data.get("info", {}).get("image_root", ".")
    by_image: dict[int, list[dict]] = {}
    for a in data["annotations"]:
        by_image.setdefault(a["image_id"], []).append(a)
    images = [im for im in data["images"] if not areas or im.get("area_name") in areas]
    images.sort(key=lambda im: im["id"])
    if limit is not None:
        images = images[:limit]
    frames = [read_frame(root, im, by_image.get(im["id"], []), scale) for im in images]
    return data, frames


def read_frame(root: Path, image: dict, annotations: list[dict], scale: float) -> Frame:
    path = root / image["file_name"]
    try:
        rgb = np.asarray(Image.open(path).convert("RGB"))
    except (FileNotFoundError, OSError) as e:
        raise DataError(f"{path}: cannot read the image of COCO image {image['id']}: {e}") from e
    h, w = image["height"], image["width"]
    if rgb.shape[:2] != (h, w):
        raise DataError(f"{path}: {rgb.shape[1]}×{rgb.shape[0]} px, the COCO entry says {w}×{h}")
    instances = np.zeros((h, w), np.int32)
    ignore = np.zeros((h, w), bool)
    # Larger first, so that a small instance drawn later stays visible where masks overlap.
    for k, a in enumerate(sorted(annotations, key=lambda a: -a.get("area", 0)), start=1):
        m = decode_segmentation(a["segmentation"], h, w).astype(bool)
        if a.get("iscrowd", 0):
            ignore |= m
        else:
            instances[m] = k
    if image.get("ignore_file"):
        ipath = root / image["ignore_file"]
        try:
            ignore |= np.asarray(Image.open(ipath).convert("L")) > 127
        except (FileNotFoundError, OSError) as e:
            raise DataError(f"{ipath}: cannot read the ignore mask: {e}") from e
    if scale != 1.0:
        sw, sh = max(1, round(w * scale)), max(1, round(h * scale))
        rgb = np.asarray(Image.fromarray(rgb).resize((sw, sh), Image.BILINEAR))
        instances = np.asarray(Image.fromarray(instances).resize((sw, sh), Image.NEAREST))
        ignore = np.asarray(Image.fromarray(ignore).resize((sw, sh), Image.NEAREST))
    return Frame(image["id"], image["file_name"], image.get("area_name", ""), w, h, rgb,
                 instances.astype(np.int32), ignore.astype(bool))


def decode_segmentation(seg, h: int, w: int) -> np.ndarray:
    """An annotation's mask as (h, w) uint8: RLE (compressed or not; numpy, `rle.py`) or polygons
    (rasterised by pycocotools, needed only for polygon annotations)."""
    if isinstance(seg, list):
        from pycocotools import mask as mask_utils

        rles = mask_utils.frPyObjects(seg, h, w)
        return mask_utils.decode(mask_utils.merge(rles))
    return rle.decode(seg)


# ------------------------------------------------------------------------------------- bottom-up targets
BACKGROUND, INTERIOR, RIM = 0, 1, 2


def unet_targets(instances: np.ndarray, ignore: np.ndarray, rim_px: int = 1) -> tuple[np.ndarray, np.ndarray,
                                                                                        np.ndarray]:
    """Per-pixel targets of the bottom-up model.

    Returns `(classes, touching, distance)`: classes 0 background / 1 interior / 2 rim (instance pixels
    within `rim_px` of another label), `IGNORE` where ignored; `touching` marks rim pixels next to
    another building (the boundaries that split instances, weighted up in the loss); `distance` is each
    instance pixel's distance to its instance's edge divided by the instance's largest one (0–1), the
    seed map of the watershed.
    """
    inst = instances
    edge = np.zeros(inst.shape, bool)
    touch = np.zeros(inst.shape, bool)
    for dy, dx in ((0, 1), (1, 0)):
        a = inst[: inst.shape[0] - dy, : inst.shape[1] - dx]
        b = inst[dy:, dx:]
        diff = a != b
        both = diff & (a > 0) & (b > 0)
        edge[: inst.shape[0] - dy, : inst.shape[1] - dx] |= diff
        edge[dy:, dx:] |= diff
        touch[: inst.shape[0] - dy, : inst.shape[1] - dx] |= both
        touch[dy:, dx:] |= both
    if rim_px > 1:
        grow = np.ones((2 * rim_px - 1, 2 * rim_px - 1), bool)
        edge = ndimage.binary_dilation(edge, grow)
        touch = ndimage.binary_dilation(touch, grow)
    fg = inst > 0
    classes = np.where(fg, np.where(edge, RIM, INTERIOR), BACKGROUND).astype(np.uint8)
    classes[ignore] = IGNORE
    touching = touch & fg
    inner = fg & ~edge
    dist = ndimage.distance_transform_edt(inner).astype(np.float32)
    if inst.max() > 0:
        peak = ndimage.maximum(dist, labels=inst, index=np.arange(inst.max() + 1)).astype(np.float32)
        peak[0] = 1.0
        dist = dist / np.maximum(peak[inst], 1.0)
    dist[~fg] = 0.0
    return classes, touching, dist
