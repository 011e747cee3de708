#!/usr/bin/env python3
"""Independent checks of insgen's COCO output with pycocotools (driven by tests/coco_*.rs and benches/rle.rs).

Every sub-command prints one JSON object on stdout; diagnostics go to stderr.

  encode   MASKS.bin INDEX.json   pycocotools.mask.encode/decode/area/toBbox/merge of row-major uint8 masks
  dataset  COCO_DIR               COCO() loads every instances_*.json; annToMask of every annotation is
                                  compared pixel for pixel with the connected component decoded from the ID
                                  map (own PNG decoder + own labelling, no insgen code); COCOeval with the
                                  ground truth submitted as predictions (score 1)
  results  GT.json OUT.json       writes a results file from the ground truth through pycocotools, half the
                                  entries with compressed, half with uncompressed counts
  bench    LABELS.bin H W N REPS  times pycocotools.mask.encode on the N instance masks of a label image

Needs numpy and pycocotools only.
"""

import contextlib
import io
import json
import struct
import sys
import time
import zlib
from collections import deque
from pathlib import Path

import numpy as np
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval


def rle_to_json(rle):
    return {"size": [int(v) for v in rle["size"]], "counts": rle["counts"].decode("ascii")}


def bbox_list(b):
    return [float(v) for v in b]


# ---------------------------------------------------------------------------------------------- encode
def cmd_encode(masks_path, index_path):
    data = np.fromfile(masks_path, dtype=np.uint8)
    index = json.loads(Path(index_path).read_text())
    out = {"masks": [], "merges": []}
    by_name = {}
    for m in index["masks"]:
        h, w, off = m["h"], m["w"], m["offset"]
        rows = data[off:off + h * w].reshape(h, w)
        fortran = np.asfortranarray(rows)
        rle = mask_utils.encode(fortran)
        by_name[m["name"]] = rle
        decoded_ours = None
        if "ours" in m:
            ours = {"size": [h, w], "counts": m["ours"].encode("ascii")}
            decoded_ours = bool(np.array_equal(mask_utils.decode(ours), rows))
        out["masks"].append({
            "name": m["name"],
            "counts": rle["counts"].decode("ascii"),
            "size": [int(v) for v in rle["size"]],
            "area": int(mask_utils.area(rle)),
            "bbox": bbox_list(mask_utils.toBbox(rle)),
            "pycocotools_decodes_ours_to_input": decoded_ours,
        })
    for g in index.get("merges", []):
        rles = [by_name[n] for n in g]
        out["merges"].append({
            "names": g,
            "union": mask_utils.merge(rles, intersect=False)["counts"].decode("ascii"),
            "intersection": mask_utils.merge(rles, intersect=True)["counts"].decode("ascii"),
        })
    return out


# --------------------------------------------------------------------------------------------- dataset
def read_png_rgb(path):
    """Minimal PNG decoder (8-bit RGB/RGBA, non-interlaced) -> (h, w, 3) uint8."""
    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG")
    pos, idat = 8, []
    width = height = None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        ctype = data[pos + 4:pos + 8]
        chunk = data[pos + 8:pos + 8 + length]
        pos += 12 + length
        if ctype == b"IHDR":
            width, height, depth, color, _, _, interlace = struct.unpack(">IIBBBBB", chunk)
            if depth != 8 or color not in (2, 6) or interlace != 0:
                raise ValueError(f"{path}: unsupported PNG (depth {depth}, colour {color}, interlace {interlace})")
            bpp = 3 if color == 2 else 4
        elif ctype == b"IDAT":
            idat.append(chunk)
        elif ctype == b"IEND":
            break
    raw = zlib.decompress(b"".join(idat))
    stride = width * bpp
    out = np.zeros((height, stride), dtype=np.uint8)
    prev = [0] * stride
    for y in range(height):
        base = y * (stride + 1)
        ft = raw[base]
        line = raw[base + 1:base + 1 + stride]
        cur = [0] * stride
        for i in range(stride):
            a = cur[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            x = line[i]
            if ft == 0:
                v = x
            elif ft == 1:
                v = x + a
            elif ft == 2:
                v = x + b
            elif ft == 3:
                v = x + (a + b) // 2
            elif ft == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if (pa <= pb and pa <= pc) else (b if pb <= pc else c)
                v = x + pred
            else:
                raise ValueError(f"{path}: bad filter {ft}")
            cur[i] = v & 0xFF
        out[y] = cur
        prev = cur
    return out.reshape(height, width, bpp)[:, :, :3]


def id_map(path):
    rgb = read_png_rgb(path).astype(np.uint32)
    return (rgb[:, :, 0] << 16) | (rgb[:, :, 1] << 8) | rgb[:, :, 2]


def components(ids, connectivity):
    """Connected components of equal non-zero ids (BFS). Returns (labels, [dict(building, area, truncated)])."""
    h, w = ids.shape
    grid = ids.tolist()
    lab = [[0] * w for _ in range(h)]
    steps = [(0, 1), (1, 0), (0, -1), (-1, 0)]
    if connectivity == 8:
        steps += [(1, 1), (1, -1), (-1, 1), (-1, -1)]
    comps = []
    for y in range(h):
        for x in range(w):
            b = grid[y][x]
            if b == 0 or lab[y][x]:
                continue
            k = len(comps) + 1
            lab[y][x] = k
            q = deque([(y, x)])
            area, border = 0, False
            while q:
                cy, cx = q.popleft()
                area += 1
                border |= cy == 0 or cx == 0 or cy == h - 1 or cx == w - 1
                for dy, dx in steps:
                    ny, nx = cy + dy, cx + dx
                    if 0 <= ny < h and 0 <= nx < w and not lab[ny][nx] and grid[ny][nx] == b:
                        lab[ny][nx] = k
                        q.append((ny, nx))
            comps.append({"building": b, "area": area, "truncated": border})
    return np.array(lab, dtype=np.int64), comps


def fill_holes(mask):
    """Mask with its holes filled: background not 4-connected to the image border becomes foreground."""
    h, w = mask.shape
    outside = np.zeros((h + 2, w + 2), dtype=bool)
    padded = np.zeros((h + 2, w + 2), dtype=bool)
    padded[1:-1, 1:-1] = mask.astype(bool)
    q = deque([(0, 0)])
    outside[0, 0] = True
    while q:
        y, x = q.popleft()
        for dy, dx in ((0, 1), (1, 0), (0, -1), (-1, 0)):
            ny, nx = y + dy, x + dx
            if 0 <= ny < h + 2 and 0 <= nx < w + 2 and not outside[ny, nx] and not padded[ny, nx]:
                outside[ny, nx] = True
                q.append((ny, nx))
    return (~outside[1:-1, 1:-1]).astype(np.uint8)


def evaluate(coco_gt, iou_type, tmp_path):
    dets = []
    for ann in coco_gt.dataset["annotations"]:
        rle = coco_gt.annToRLE(ann)
        dets.append({
            "image_id": ann["image_id"],
            "category_id": ann["category_id"],
            "segmentation": {"size": [int(v) for v in rle["size"]], "counts": rle["counts"].decode("ascii")
                             if isinstance(rle["counts"], bytes) else rle["counts"]},
            "bbox": ann["bbox"],
            "score": 1.0,
        })
    Path(tmp_path).write_text(json.dumps(dets))
    densest = max(np.bincount([a["image_id"] for a in coco_gt.dataset["annotations"]]).max(), 1)
    with contextlib.redirect_stdout(io.StringIO()) as log:
        coco_dt = coco_gt.loadRes(str(tmp_path))
        ev = COCOeval(coco_gt, coco_dt, iou_type)
        ev.params.maxDets = [1, 10, int(max(100, densest))]
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    sys.stderr.write(log.getvalue())
    return {"AP": float(ev.stats[0]), "AP50": float(ev.stats[1]), "AP75": float(ev.stats[2]),
            "max_dets": int(max(100, densest))}


def cmd_dataset(coco_dir):
    coco_dir = Path(coco_dir)
    report = {"files": {}}
    for split in ("train", "val", "test"):
        path = coco_dir / f"instances_{split}.json"
        with contextlib.redirect_stdout(io.StringIO()):
            coco = COCO(str(path))
        root = Path(coco.dataset["info"]["image_root"])
        root = root if root.is_absolute() else coco_dir / root
        per_building = coco.dataset["info"]["annotation_unit"] == "building"
        r = {"images": len(coco.dataset["images"]), "annotations": len(coco.dataset["annotations"]),
             "checked": 0, "mismatches": [], "unannotated": [], "polygon_pixel_errors": 0,
             "polygon_annotations": 0, "polygon_exact": 0}
        for img in coco.dataset["images"]:
            mask_file = root / img["mask_file"]
            ids = id_map(mask_file)
            inst = json.loads(mask_file.with_name(mask_file.name[:-4] + ".instances.json").read_text())
            conn = int(inst["connectivity"])
            min_px = inst["min_component_area_px"]
            lab, comps = components(ids, conn)
            listed = {k + 1 for k, c in enumerate(comps) if c["area"] >= min_px}
            covered = set()
            for ann in coco.loadAnns(coco.getAnnIds(imgIds=[img["id"]])):
                got = coco.annToMask(ann)
                is_poly = isinstance(ann["segmentation"], list)
                exact = got
                if is_poly:
                    exact = mask_utils.decode(ann["mask_rle"] | {"counts": ann["mask_rle"]["counts"].encode()})
                col_x, col_y = np.nonzero(exact.T)  # column-major order: first pixel first
                if len(col_x) == 0:
                    r["mismatches"].append({"ann": ann["id"], "why": "empty mask"})
                    continue
                first = lab[col_y[0], col_x[0]]
                if per_building:
                    ks = {k for k in listed if comps[k - 1]["building"] == ann["building_id"]}
                    expected = np.isin(lab, list(ks)).astype(np.uint8)
                else:
                    ks = {int(first)}
                    expected = (lab == first).astype(np.uint8)
                    if comps[first - 1]["building"] != ann["building_id"]:
                        r["mismatches"].append({"ann": ann["id"], "why": "building id differs"})
                covered |= ks
                if not np.array_equal(exact, expected):
                    r["mismatches"].append({"ann": ann["id"], "why": "mask differs",
                                            "pixels": int((exact != expected).sum())})
                if int(ann["area"]) != int(expected.sum()):
                    r["mismatches"].append({"ann": ann["id"], "why": "area differs"})
                exp_trunc = any(comps[k - 1]["truncated"] for k in ks)
                if bool(ann["truncated"]) != exp_trunc:
                    r["mismatches"].append({"ann": ann["id"], "why": "truncated differs"})
                if is_poly:
                    r["polygon_annotations"] += 1
                    diff = int((got != fill_holes(expected)).sum())
                    r["polygon_pixel_errors"] += diff
                    r["polygon_exact"] += int(diff == 0)
                r["checked"] += 1
            for k in sorted(listed - covered):
                c = comps[k - 1]
                r["unannotated"].append({"image": img["id"], "building": c["building"], "area": c["area"],
                                         "truncated": c["truncated"]})
        if r["annotations"] > 0:
            r["segm"] = evaluate(coco, "segm", coco_dir / f".eval_{split}_segm.json")
            r["bbox"] = evaluate(coco, "bbox", coco_dir / f".eval_{split}_bbox.json")
            for suffix in ("segm", "bbox"):
                (coco_dir / f".eval_{split}_{suffix}.json").unlink()
        report["files"][split] = r
    return report


# --------------------------------------------------------------------------------------------- results
def uncompressed_counts(mask):
    """COCO uncompressed RLE counts (column-major runs, starting with zeros) of a (h, w) 0/1 array."""
    flat = mask.reshape(-1, order="F").astype(np.int8)
    if flat.size == 0:
        return [0]
    change = np.flatnonzero(np.diff(flat)) + 1
    edges = [0] + change.tolist() + [flat.size]
    counts = [] if flat[0] == 0 else [0]
    counts += [int(b - a) for a, b in zip(edges[:-1], edges[1:])]
    return counts


def cmd_results(gt_path, out_path):
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO(str(gt_path))
    out = []
    for i, ann in enumerate(coco.dataset["annotations"]):
        m = coco.annToMask(ann)
        if i % 2 == 0:
            rle = mask_utils.encode(np.asfortranarray(m))
            seg = rle_to_json(rle)
        else:
            seg = {"size": [int(m.shape[0]), int(m.shape[1])], "counts": uncompressed_counts(m)}
        out.append({"image_id": ann["image_id"], "category_id": 1, "segmentation": seg,
                    "score": round(1.0 - 0.5 * i / max(1, len(coco.dataset["annotations"])), 6),
                    "annotation_id": ann["id"]})
    Path(out_path).write_text(json.dumps(out))
    return {"written": len(out)}


# ----------------------------------------------------------------------------------------------- bench
def cmd_bench(labels_path, h, w, n, reps):
    h, w, n, reps = int(h), int(w), int(n), int(reps)
    labels = np.fromfile(labels_path, dtype="<u4").reshape(h, w)
    # Encode only: the masks are prepared beforehand as one Fortran (h, w, n) stack (pycocotools' best case).
    stack = np.zeros((h, w, n), dtype=np.uint8, order="F")
    for k in range(n):
        stack[:, :, k] = labels == k + 1
    best_encode = best_full = float("inf")
    for _ in range(reps):
        t = time.perf_counter()
        rles = mask_utils.encode(stack)
        best_encode = min(best_encode, time.perf_counter() - t)
    for _ in range(reps):
        t = time.perf_counter()
        full = [mask_utils.encode(np.asfortranarray(labels == k + 1, dtype=np.uint8)) for k in range(n)]
        best_full = min(best_full, time.perf_counter() - t)
    return {"encode_stack_s": best_encode, "per_instance_from_labels_s": best_full,
            "counts": [r["counts"].decode("ascii") for r in rles],
            "counts_full_equal": [a["counts"] == b["counts"] for a, b in zip(rles, full)] == [True] * n}


def main(argv):
    if len(argv) < 2:
        sys.stderr.write(__doc__)
        return 2
    cmd, args = argv[1], argv[2:]
    table = {"encode": cmd_encode, "dataset": cmd_dataset, "results": cmd_results, "bench": cmd_bench}
    if cmd not in table:
        sys.stderr.write(f"unknown command {cmd!r}\n{__doc__}")
        return 2
    json.dump(table[cmd](*args), sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
