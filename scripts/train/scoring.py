"""Scoring a results file against the COCO ground truth, and the RGB | truth | prediction picture.

- `AP`, `AP50`, `AP75`: pycocotools COCOeval, iouType `segm`, on the images of the chosen areas.
- `building_iou`: IoU of the union of the predicted masks scoring ≥ 0.3 with the union of the
  annotations (crowd pixels left out): how well the model finds building pixels at all;
  `all_building_iou` is what calling every pixel a building would score (the share of building pixels).
- `precision_50`, `recall_50`: one-to-one matches at mask IoU ≥ 0.5 (greedy by score, predictions
  scoring ≥ 0.3): how often an instance is exactly one building.
- `mask_zoom`: per image, the scale about the principal point that makes the union of the true masks
  fit the union of the predicted ones best (IoU, crowd pixels left out), searched in
  [1 − ZOOM_REACH, 1 + ZOOM_REACH]; median and quartiles over the images where both show buildings.
  Above 1 the model's masks reach past the buildings' edges away from the principal point, which a
  localizer cannot tell from a camera moved forward (0.25 % is a metre at 400 m): measured on frames
  whose poses are known (the validation split), it is what `insgen eval-loc --prediction-zoom` undoes.
- `outline_f1`: how well the outline of the predicted building pixels (scoring ≥ 0.3) lies on the true
  one: pixels with a background 4-neighbour inside the image (crowd pixels left out), a pixel of one
  outline counted as found when the other has a pixel within 1 (`1px`) or 2 px (`2px`, Euclidean); the
  F-score of those shares, pooled over the images (pixels of the images' own size: compare models at
  one resolution). A localizer places the buildings by their edges, and
  AP or the building IoU do not say how well a model draws them (`insgen eval-loc`'s segmenter-like
  masks report the same measure in their debug log).
- `score_honesty`: whether a prediction's score says how good its mask is, over every prediction:
  the Spearman rank correlation of the scores with each mask's best IoU with a true instance, and per
  band of scores the predictions, their mean best IoU and the share at IoU ≥ 0.5. `honest` when the
  correlation is at least HONEST_RHO and the mean IoU rises from band to band: then the scores can weight
  the instances of a localizer's cost (`insgen eval-loc --weighting conf`).
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval
from scipy import ndimage, stats

import data as ds

SCORE_MIN = 0.3  # predictions counted by building_iou, P/R@0.5 and mask_zoom
ZOOM_REACH = 0.02  # mask_zoom searches 1 ± this (a segmenter's scale error is a few per mille)
SCORE_BANDS = (0.0, 0.5, 0.7, 0.9, 1.0)  # score_honesty's bands, the last one closed
HONEST_RHO = 0.3  # score_honesty: the rank correlation from which scores count as honest


def load(coco_json: Path, results: Path, areas):
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO(str(coco_json))
    img_ids = sorted(i for i, im in gt.imgs.items() if not areas or im.get("area_name") in areas)
    if not img_ids:
        raise ds.DataError(f"{coco_json}: no image of areas {areas}")
    preds = json.loads(Path(results).read_text())
    preds = [p for p in preds if p["image_id"] in set(img_ids)]
    return gt, img_ids, preds


def score(coco_json: Path, results: Path, areas=None) -> dict:
    gt, img_ids, preds = load(coco_json, results, areas)
    report = {"coco": str(coco_json), "results": str(results), "areas": areas or "all", "images": len(img_ids),
              "annotations": len(gt.getAnnIds(imgIds=img_ids, iscrowd=False)), "predictions": len(preds)}
    if preds:
        with contextlib.redirect_stdout(io.StringIO()):
            dt = gt.loadRes(preds)
            ev = COCOeval(gt, dt, "segm")
            ev.params.imgIds = img_ids
            ev.evaluate()
            ev.accumulate()
            ev.summarize()
        report.update({"AP": round(float(ev.stats[0]), 4), "AP50": round(float(ev.stats[1]), 4),
                       "AP75": round(float(ev.stats[2]), 4)})
    else:
        report.update({"AP": 0.0, "AP50": 0.0, "AP75": 0.0})
    report.update(pixel_and_match_scores(gt, img_ids, preds))
    report["score_honesty"] = score_honesty(gt, img_ids, preds)
    return report


def score_honesty(gt: COCO, img_ids: list[int], preds: list[dict]) -> dict:
    """How well the predictions' scores rank their masks: see the module's docstring."""
    scores, ious = [], []
    by_img: dict[int, list[dict]] = {}
    for p in preds:
        by_img.setdefault(p["image_id"], []).append(p)
    for i in img_ids:
        ps = by_img.get(i, [])
        if not ps:
            continue
        truth = [gt.annToRLE(a) for a in gt.loadAnns(gt.getAnnIds(imgIds=[i])) if not a.get("iscrowd", 0)]
        best = (np.asarray(mask_utils.iou([p["segmentation"] for p in ps], truth, [0] * len(truth))).max(axis=1)
                if truth else np.zeros(len(ps)))
        scores += [float(p["score"]) for p in ps]
        ious += [float(v) for v in best]
    s, u = np.asarray(scores), np.asarray(ious)
    bands = []
    for k, (lo, hi) in enumerate(zip(SCORE_BANDS, SCORE_BANDS[1:])):
        inside = (s >= lo) & ((s <= hi) if k == len(SCORE_BANDS) - 2 else (s < hi))
        n = int(inside.sum())
        bands.append({"scores": [lo, hi], "predictions": n,
                      "mean_iou": round(float(u[inside].mean()), 4) if n else None,
                      "share_iou_50": round(float((u[inside] >= 0.5).mean()), 4) if n else None})
    rho = None
    if len(s) >= 3 and np.ptp(s) > 0 and np.ptp(u) > 0:
        rho = round(float(stats.spearmanr(s, u).statistic), 4)
    means = [b["mean_iou"] for b in bands if b["mean_iou"] is not None]
    rising = len(means) >= 2 and all(a <= b for a, b in zip(means, means[1:]))
    return {"spearman": rho, "bands": bands, "honest": rho is not None and rho >= HONEST_RHO and rising}


def pixel_and_match_scores(gt: COCO, img_ids: list[int], preds: list[dict]) -> dict:
    inter = union = truth_px = valid_px = 0
    tp = n_pred = n_gt = 0
    zooms = []
    outlines = np.zeros(6, np.int64)  # truth, predicted, truth near (1, 2 px), predicted near (1, 2 px)
    by_img = scored_by_image(preds)
    for i in img_ids:
        im = gt.imgs[i]
        h, w = im["height"], im["width"]
        truth, crowd, pm, gu, pu = image_masks(gt, i, by_img.get(i, []))
        truth_px += int((gu & ~crowd).sum())
        valid_px += int((~crowd).sum())
        inter += int((gu & pu & ~crowd).sum())
        union += int(((gu | pu) & ~crowd).sum())
        n_pred += len(pm)
        n_gt += len(truth)
        tp += greedy_matches(pm, truth)
        outlines += outline_counts(gu, pu, ~crowd)
        if gu.any() and pu.any():
            k = im.get("intrinsics") or {}
            zooms.append(best_zoom(gu, pu, ~crowd, k.get("cx_px", w / 2), k.get("cy_px", h / 2)))
    q = [round(float(v), 5) for v in np.percentile(zooms, [25, 50, 75])] if zooms else [None] * 3
    return {"building_iou": round(inter / union, 4) if union else None,
            "all_building_iou": round(truth_px / valid_px, 4) if valid_px else None,
            "precision_50": round(tp / n_pred, 4) if n_pred else 0.0,
            "recall_50": round(tp / n_gt, 4) if n_gt else 0.0,
            "mask_zoom": {"median": q[1], "q25": q[0], "q75": q[2], "images": len(zooms)},
            "outline_f1": {f"{d}px": outline_f1(outlines, d) for d in (1, 2)}}


def scored_by_image(preds: list[dict]) -> dict[int, list[dict]]:
    """The predictions scoring at least SCORE_MIN, per image."""
    by_img: dict[int, list[dict]] = {}
    for p in preds:
        if p["score"] >= SCORE_MIN:
            by_img.setdefault(p["image_id"], []).append(p)
    return by_img


def image_masks(gt: COCO, i: int, ps: list[dict]):
    """Image i's true masks (crowd left out), crowd pixels, predicted masks (best score first), and the
    unions of the true and the predicted ones."""
    anns = gt.loadAnns(gt.getAnnIds(imgIds=[i]))
    h, w = gt.imgs[i]["height"], gt.imgs[i]["width"]
    crowd = np.zeros((h, w), bool)
    truth = [gt.annToMask(a).astype(bool) for a in anns if not a.get("iscrowd", 0)]
    for a in anns:
        if a.get("iscrowd", 0):
            crowd |= gt.annToMask(a).astype(bool)
    pm = [mask_utils.decode(p["segmentation"]).astype(bool) for p in sorted(ps, key=lambda p: -p["score"])]
    gu = np.logical_or.reduce(truth) if truth else np.zeros((h, w), bool)
    pu = np.logical_or.reduce(pm) if pm else np.zeros((h, w), bool)
    return truth, crowd, pm, gu, pu


def outline_f1_per_frame(coco_json: Path, results: Path, areas=None) -> dict[str, float | None]:
    """Each image's `outline_f1` within 1 px, by frame name (the image's `frame`, else its file's stem):
    what the closed loop's report sets against each frame's localization."""
    gt, img_ids, preds = load(coco_json, results, areas)
    by_img = scored_by_image(preds)
    out = {}
    for i in img_ids:
        _, crowd, _, gu, pu = image_masks(gt, i, by_img.get(i, []))
        im = gt.imgs[i]
        out[im.get("frame") or Path(im["file_name"]).stem] = outline_f1(outline_counts(gu, pu, ~crowd), 1)
    return out


FOUR = ndimage.generate_binary_structure(2, 1)
NEAR = {d: np.add.outer(np.arange(-d, d + 1) ** 2, np.arange(-d, d + 1) ** 2) <= d * d for d in (1, 2)}


def outline_counts(truth: np.ndarray, pred: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Outline pixels of the two masks (pixels with a 4-neighbour inside the image outside the mask) in
    `valid`, and those of each with one of the other's within 1 and 2 px: see `outline_f1`."""
    def outline(m):
        return m & ~ndimage.binary_erosion(m, FOUR, border_value=1) & valid
    t, p = outline(truth), outline(pred)
    near = [(a & ndimage.binary_dilation(b, NEAR[d])).sum() for a, b in ((t, p), (p, t)) for d in (1, 2)]
    return np.array([t.sum(), p.sum(), near[0], near[1], near[2], near[3]], np.int64)


def outline_f1(counts: np.ndarray, tolerance_px: int):
    """The F-score within `tolerance_px` (1 or 2) of `outline_counts`' counts (summed over images or
    not): of the shares of predicted and of true outline pixels found; None without outlines."""
    truth, pred = counts[0], counts[1]
    if pred == 0 or truth == 0:
        return None if pred == truth == 0 else 0.0
    rc, pr = counts[1 + tolerance_px] / truth, counts[3 + tolerance_px] / pred
    return round(float(2 * pr * rc / (pr + rc)), 4) if pr + rc > 0 else 0.0


def best_zoom(truth: np.ndarray, pred: np.ndarray, valid: np.ndarray, cx: float, cy: float) -> float:
    """The scale s about (cx, cy) (pixel edges; the centre of pixel i is i + 0.5) whose zoomed `truth`
    (pixel p shows the truth at c + (p − c)/s, bilinear, ≥ 0.5) has the highest IoU with `pred` over
    the `valid` pixels: a grid of steps of 0.001 over 1 ± ZOOM_REACH, then steps of 0.0001 about the best.

    Only pixels that a zoom in that range can change are resampled (those nearer to the truth's
    boundary than their displacement), so a 1080p frame takes a fraction of a second."""
    h, w = truth.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    dx, dy = xx + 0.5 - cx, yy + 0.5 - cy
    to_edge = np.where(truth, ndimage.distance_transform_edt(truth), ndimage.distance_transform_edt(~truth))
    reach = np.hypot(dx, dy) * ZOOM_REACH / (1 - ZOOM_REACH) + 1.5
    band = (to_edge <= reach) & valid
    fixed = ~band & valid
    inter0 = int((truth & pred & fixed).sum())
    union0 = int(((truth | pred) & fixed).sum())
    bx, by, bp = dx[band], dy[band], pred[band]
    tf = truth.astype(np.float32)

    def iou(s: float) -> float:
        coords = [cy + by / s - 0.5, cx + bx / s - 0.5]
        z = ndimage.map_coordinates(tf, coords, order=1, mode="constant", cval=0.0) >= 0.5
        i = inter0 + int((z & bp).sum())
        u = union0 + int((z | bp).sum())
        return i / u if u else 0.0

    coarse = np.round(np.arange(1 - ZOOM_REACH, 1 + ZOOM_REACH + 1e-9, 0.001), 6)
    best = max(coarse, key=lambda s: (iou(s), -abs(s - 1)))
    fine = np.round(best + np.arange(-0.001, 0.001 + 1e-9, 0.0001), 6)
    return float(max(fine, key=lambda s: (iou(s), -abs(s - 1))))


def greedy_matches(pred: list[np.ndarray], truth: list[np.ndarray]) -> int:
    used = [False] * len(truth)
    tp = 0
    areas = [t.sum() for t in truth]
    for p in pred:
        pa = p.sum()
        best, best_iou = -1, 0.5
        for j, t in enumerate(truth):
            if used[j]:
                continue
            i = (p & t).sum()
            if i == 0:
                continue
            iou = i / (pa + areas[j] - i)
            if iou >= best_iou:
                best, best_iou = j, iou
        if best >= 0:
            used[best] = True
            tp += 1
    return tp


# ------------------------------------------------------------------------------------------------ sheet
def colours(n: int) -> np.ndarray:
    rng = np.random.default_rng(7)
    c = rng.integers(60, 256, size=(n + 1, 3)).astype(np.uint8)
    c[0] = 0
    return c


def paint(masks: list[np.ndarray], rgb: np.ndarray) -> np.ndarray:
    """Instances in distinct colours over the darkened photo, with their outlines in white."""
    out = (rgb.astype(np.float32) * 0.25).astype(np.uint8)
    ids = np.zeros(rgb.shape[:2], np.int32)
    for k, m in enumerate(masks, start=1):
        ids[m] = k
    pal = colours(len(masks))
    col = pal[ids]
    fg = ids > 0
    out[fg] = (0.75 * col[fg] + 0.25 * rgb[fg]).astype(np.uint8)
    edge = np.zeros_like(fg)
    edge[:, 1:] |= ids[:, 1:] != ids[:, :-1]
    edge[1:, :] |= ids[1:, :] != ids[:-1, :]
    out[edge] = 255
    return out


def sheet(coco_json: Path, results: Path, out: Path, areas=None, count: int = 6, min_score: float = 0.3) -> None:
    gt, img_ids, preds = load(coco_json, results, areas)
    root = Path(coco_json).parent / gt.dataset.get("info", {}).get("image_root", ".")
    picks = [img_ids[round(k * (len(img_ids) - 1) / max(count - 1, 1))] for k in range(min(count, len(img_ids)))]
    rows = []
    for i in dict.fromkeys(picks):
        im = gt.imgs[i]
        rgb = np.asarray(Image.open(root / im["file_name"]).convert("RGB"))
        ps = [p for p in preds if p["image_id"] == i and p["score"] >= min_score]
        truth, crowd, pm, _, _ = image_masks(gt, i, ps)
        pm.reverse()  # the best score painted last, on top
        errors, missed, extra = building_errors(truth, pm, rgb, crowd)
        gap = np.full((rgb.shape[0], 4, 3), 255, np.uint8)
        row = np.concatenate([rgb, gap, paint(truth, rgb), gap, paint(pm, rgb), gap, errors], axis=1)
        label = (f"{im.get('area_name', '')}/{im.get('frame', i)}: {len(truth)} true, {len(pm)} predicted; "
                 f"building px missed {100 * missed:.0f} %, extra {100 * extra:.0f} %")
        rows.append(caption(row, label))
    w = max(r.shape[1] for r in rows)
    head = caption(np.zeros((0, w, 3), np.uint8), "RGB | truth (annotations) | prediction (score >= "
                   f"{min_score}); each instance one colour, outlines white | building pixels: both grey, "
                   "missed red, extra blue, crowd regions (not counted) dark")
    pic = np.concatenate([head] + rows, axis=0)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp.png")
    Image.fromarray(pic).save(tmp)
    tmp.replace(out)


def building_errors(truth: list, predicted: list, rgb: np.ndarray, ignore: np.ndarray | None = None):
    """The photo darkened, with the building pixels both masks hold grey, those only the truth holds
    (missed) red and those only the prediction holds (extra) blue; and the missed and extra pixels as
    shares of the true building pixels. Pixels under `ignore` (crowd annotations: regions the labels
    leave open) count neither way and are drawn darker still."""
    shape = rgb.shape[:2]
    keep = ~ignore if ignore is not None else np.ones(shape, bool)
    t = (np.logical_or.reduce(truth) if truth else np.zeros(shape, bool)) & keep
    p = (np.logical_or.reduce(predicted) if predicted else np.zeros(shape, bool)) & keep
    out = rgb // 2
    out[t & p] = (200, 200, 200)
    out[t & ~p] = (255, 60, 60)
    out[~t & p] = (60, 120, 255)
    out[~keep] = rgb[~keep] // 5
    n = max(int(t.sum()), 1)
    return out, float((t & ~p).sum()) / n, float((~t & p).sum()) / n


def caption(row: np.ndarray, text: str) -> np.ndarray:
    bar = Image.new("RGB", (row.shape[1], 18), (30, 30, 30))
    ImageDraw.Draw(bar).text((4, 3), text, fill=(255, 255, 255))
    return np.concatenate([np.asarray(bar), row], axis=0)
