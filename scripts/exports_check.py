#!/usr/bin/env python3
"""Independent checks of insgen's dataset exports with the formats' own Python clients.

Each subcommand prints one JSON object on stdout (the Rust integration tests in tests/it/exports.rs
parse it and assert on it) and exits non-zero only when a client refuses to read the files.

  colmap DIR POSES_JSONL   pycolmap.Reconstruction(DIR): cameras, images and poses against poses.jsonl
  panoptic COCO_DIR        panopticapi (rgb2id, pq_compute) + pycocotools: every panoptic_<split>.json
  hf COCO_DIR              Hugging Face datasets: load_dataset(COCO_DIR), nothing else (the dataset card's
                           front matter names the splits); rows, decoded photos and every object against
                           instances_<split>.json
  yolo DATA_YAML COCO_DIR  Ultralytics' label rules (reimplemented from ultralytics/data/utils.py,
                           verify_image_label and img2label_paths; the ultralytics package pulls in
                           torch) + an even-odd rasteriser: IoU of every label line with its instance

References: COLMAP "Output format"; panopticapi/utils.py and evaluation.py (cocodataset/panopticapi,
via the panopticapi-lite package); ultralytics/data/utils.py.
"""

import glob
import json
import os
import sys

import numpy as np


def colmap(model_dir, poses_jsonl):
    import pycolmap

    rec = pycolmap.Reconstruction(model_dir)
    poses = {}
    with open(poses_jsonl) as f:
        for line in f:
            if line.strip():
                r = json.loads(line)
                poses[r["name"] + ".png"] = r
    out = {
        "pycolmap": pycolmap.__version__,
        "cameras": len(rec.cameras),
        "images": len(rec.images),
        "points3D": len(rec.points3D),
        "unmatched": [],
        "max_quat_diff": 0.0,
        "max_t_diff_m": 0.0,
        "max_centre_diff_m": 0.0,
        "max_rotation_diff": 0.0,
        "max_intrinsics_diff_px": 0.0,
    }
    for image in rec.images.values():
        r = poses.get(image.name)
        if r is None:
            out["unmatched"].append(image.name)
            continue
        cfw = image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
        qx, qy, qz, qw = (float(v) for v in cfw.rotation.quat)  # Eigen order: x, y, z, w
        q = np.array([qw, qx, qy, qz])
        q_ref = np.array(r["colmap_qvec"])
        if np.dot(q, q_ref) < 0:
            q = -q
        out["max_quat_diff"] = max(out["max_quat_diff"], float(np.abs(q - q_ref).max()))
        t = np.array(cfw.translation, dtype=float)
        out["max_t_diff_m"] = max(out["max_t_diff_m"], float(np.abs(t - np.array(r["colmap_tvec"])).max()))
        # The camera-to-world matrix of poses.jsonl: R_cw = R_wc^T, centre C = -R_wc^T t.
        rot = np.array(cfw.rotation.matrix())
        c2w = np.array(r["cam_to_world_enu"])
        out["max_rotation_diff"] = max(out["max_rotation_diff"], float(np.abs(rot.T - c2w[:3, :3]).max()))
        centre = -rot.T @ t
        out["max_centre_diff_m"] = max(out["max_centre_diff_m"], float(np.abs(centre - c2w[:3, 3]).max()))
        cam = rec.cameras[image.camera_id]
        k = r["intrinsics"]
        ref = [k["fx_px"], k["fy_px"], k["cx_px"], k["cy_px"]]
        d = max(abs(float(a) - b) for a, b in zip(cam.params, ref))
        d = max(d, abs(cam.width - k["width_px"]), abs(cam.height - k["height_px"]))
        out["max_intrinsics_diff_px"] = max(out["max_intrinsics_diff_px"], float(d))
        out.setdefault("model", cam.model.name if hasattr(cam.model, "name") else str(cam.model))
    out["poses"] = len(poses)
    print(json.dumps(out))


def _bbox(mask):
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return [0.0, 0.0, 0.0, 0.0]
    return [float(xs.min()), float(ys.min()), float(xs.max() - xs.min() + 1), float(ys.max() - ys.min() + 1)]


def panoptic(coco_dir):
    from PIL import Image
    from panopticapi.evaluation import pq_compute
    from panopticapi.utils import rgb2id
    from pycocotools import mask as mask_utils

    out = {"files": {}}
    for split in ("train", "val", "test"):
        pj = os.path.join(coco_dir, f"panoptic_{split}.json")
        if not os.path.exists(pj):
            continue
        with open(pj) as f:
            pan = json.load(f)
        with open(os.path.join(coco_dir, f"instances_{split}.json")) as f:
            inst = json.load(f)
        folder = os.path.join(coco_dir, f"panoptic_{split}")
        anns = {a["id"]: a for a in inst["annotations"]}
        image_root = os.path.join(coco_dir, inst["info"]["image_root"])
        images = {im["id"]: im for im in pan["images"]}
        r = {
            "images": len(pan["images"]),
            "same_images": pan["images"] == inst["images"],
            "segments": 0,
            "problems": [],
            "isthing": [c["isthing"] for c in pan["categories"]],
        }
        stuff_id = next(c["id"] for c in pan["categories"] if c["isthing"] == 0)
        for a in pan["annotations"]:
            im = images[a["image_id"]]
            png = np.array(Image.open(os.path.join(folder, a["file_name"])).convert("RGB"))
            ids = rgb2id(png)
            idmap_rgb = np.array(Image.open(os.path.join(image_root, im["mask_file"])).convert("RGB")).astype(np.int64)
            building = (idmap_rgb[..., 0] << 16) | (idmap_rgb[..., 1] << 8) | idmap_rgb[..., 2]
            present = set(int(v) for v in np.unique(ids)) - {0}
            listed = {s["id"] for s in a["segments_info"]}
            if present != listed:
                r["problems"].append(f"image {im['id']}: PNG ids {sorted(present)} vs JSON {sorted(listed)}")
            for s in a["segments_info"]:
                r["segments"] += 1
                m = ids == s["id"]
                if int(m.sum()) != s["area"] or _bbox(m) != [float(v) for v in s["bbox"]]:
                    r["problems"].append(f"segment {s['id']}: area/bbox {int(m.sum())} {_bbox(m)} vs {s['area']} {s['bbox']}")
                if s["category_id"] == stuff_id:
                    if not np.array_equal(m, building == 0):
                        r["problems"].append(f"image {im['id']}: background segment is not the ID map's 0 pixels")
                    continue
                if s["iscrowd"]:
                    ref = np.zeros_like(m)
                    for aid in s["annotation_ids"]:
                        a_i = anns[aid]
                        m_i = mask_utils.decode(a_i.get("mask_rle") or a_i["segmentation"]).astype(bool)
                        ref |= m_i
                        if not a_i["iscrowd"] or not np.all(building[m_i] == a_i["building_id"]):
                            r["problems"].append(f"segment {s['id']}: merges annotation {aid}, not crowd or not its building")
                    if not np.array_equal(ref, m):
                        r["problems"].append(f"crowd segment {s['id']}: pixels differ from its annotations'")
                    r["crowd_segments"] = r.get("crowd_segments", 0) + 1
                    continue
                inst_ann = anns.get(s["id"])
                if inst_ann is None:
                    r["problems"].append(f"segment {s['id']}: no instance annotation with this id")
                    continue
                seg = inst_ann.get("mask_rle") or inst_ann["segmentation"]
                ref = mask_utils.decode(seg).astype(bool)
                if not np.array_equal(ref, m):
                    r["problems"].append(f"segment {s['id']}: pixels differ from the instance mask")
                if not np.all(building[m] == inst_ann["building_id"]) or s["building_id"] != inst_ann["building_id"]:
                    r["problems"].append(f"segment {s['id']}: not building {inst_ann['building_id']} in the ID map")
                if s["iscrowd"] != inst_ann["iscrowd"] or s["category_id"] != inst_ann["category_id"]:
                    r["problems"].append(f"segment {s['id']}: iscrowd/category differ from the instance")
        # The panoptic API's own reader and metric: the ground truth scored against itself.
        if r["segments"] > 0:
            import contextlib
            import io

            with contextlib.redirect_stdout(io.StringIO()):
                res = pq_compute(pj, pj, folder, folder)
            r["pq_things"] = res["Things"]["pq"]
            r["pq_stuff"] = res["Stuff"]["pq"]
            r["pq"] = res["All"]["pq"]
            r["sq"] = res["All"]["sq"]
            r["rq"] = res["All"]["rq"]
            r["pq_n"] = res["All"]["n"]
        out["files"][split] = r
    print(json.dumps(out))


# --- Ultralytics' rules, reimplemented from ultralytics/data/utils.py -----------------------------------
IMG_FORMATS = {"bmp", "dng", "jpeg", "jpg", "mpo", "png", "tif", "tiff", "webp", "pfm", "heic"}


def img2label_paths(img_paths):
    sa, sb = f"{os.sep}images{os.sep}", f"{os.sep}labels{os.sep}"
    return [sb.join(x.rsplit(sa, 1)).rsplit(".", 1)[0] + ".txt" for x in img_paths]


def verify_image_label(im_file, lb_file, num_cls):
    """verify_image_label's checks for a segment dataset; returns (shape_hw, classes, segments)."""
    from PIL import Image

    im = Image.open(im_file)
    im.verify()
    shape = (im.size[1], im.size[0])
    assert (shape[0] > 9) & (shape[1] > 9), f"image size {shape} <10 pixels"
    assert im.format.lower() in IMG_FORMATS, f"invalid image format {im.format}"
    assert os.path.isfile(lb_file), f"label missing: {lb_file}"
    with open(lb_file, encoding="utf-8") as f:
        lb = [x.split() for x in f.read().strip().splitlines() if len(x)]
    segments = []
    if lb:
        assert all(len(x) > 6 for x in lb), "a line with <= 6 fields would make the file a box file"
        classes = np.array([x[0] for x in lb], dtype=np.float32)
        segments = [np.array(x[1:], dtype=np.float32).reshape(-1, 2) for x in lb]
        pts = np.concatenate(segments)
        assert pts.max() <= 1.01, "non-normalized or out of bounds coordinates"
        assert pts.min() >= -0.01 and classes.min() >= 0, "negative class labels or coordinates"
        assert classes.max() < num_cls, f"label class {int(classes.max())} exceeds class count {num_cls}"
        # Duplicate rows: verify_image_label compares (class, box) rows; boxes from segments.
        boxes = np.array([[c, *s.min(0), *s.max(0)] for c, s in zip(classes, segments)])
        assert len(np.unique(boxes, axis=0)) == len(lb), "duplicate labels (Ultralytics would drop them)"
        return shape, classes, segments
    return shape, np.zeros(0), []


def even_odd_fill(poly_px, h, w):
    """Pixels whose centre is inside the polygon (even-odd rule), as a boolean (h, w) array."""
    ys = np.arange(h) + 0.5
    xs = np.arange(w) + 0.5
    inside = np.zeros((h, w), dtype=bool)
    a = poly_px
    b = np.roll(poly_px, -1, axis=0)
    for (ax, ay), (bx, by) in zip(a, b):
        if ay == by:
            continue
        rows = (ys >= min(ay, by)) & (ys < max(ay, by))
        if not rows.any():
            continue
        x_cross = ax + (ys[rows] - ay) * (bx - ax) / (by - ay)
        inside[rows] ^= xs[None, :] < x_cross[:, None]
    return inside


def yolo(data_yaml, coco_dir):
    import yaml
    from PIL import Image
    from pycocotools import mask as mask_utils

    with open(data_yaml) as f:
        data = yaml.safe_load(f)
    for k in ("train", "val"):
        assert k in data, f"'{k}:' key missing (Ultralytics requires train and val)"
    assert "names" in data, "'names' missing"
    names = data["names"]
    nc = len(names)
    root = data.get("path") or os.path.dirname(data_yaml)
    out = {"names": names, "splits": {}}
    for split in ("train", "val", "test"):
        if not data.get(split):
            continue
        img_dir = os.path.join(root, data[split])
        files = sorted(
            x for x in glob.glob(os.path.join(img_dir, "**", "*.*"), recursive=True)
            if x.rsplit(".", 1)[-1].lower() in IMG_FORMATS
        )
        inst_file = os.path.join(coco_dir, f"instances_{split}.json")
        r = {"images": len(files), "instances": 0, "min_iou": 1.0, "problems": [], "max_vertices": 0}
        if not os.path.exists(inst_file):
            out["splits"][split] = r
            continue
        with open(inst_file) as f:
            inst = json.load(f)
        image_root = os.path.join(coco_dir, inst["info"]["image_root"])
        by_key = {(im["area_name"], im["camera"], im["frame"]): im for im in inst["images"]}
        anns = {}
        for a in inst["annotations"]:
            if not a["iscrowd"]:
                anns.setdefault(a["image_id"], []).append(a)
        r["coco_images"] = len(inst["images"])
        for im_file, lb_file in zip(files, img2label_paths(files)):
            rel = os.path.relpath(im_file, img_dir)
            area, camera, fname = rel.split(os.sep)
            im = by_key[(area, camera, fname.rsplit(".", 1)[0])]
            try:
                (h, w), classes, segments = verify_image_label(im_file, lb_file, nc)
            except AssertionError as e:
                r["problems"].append(f"{im_file}: {e}")
                continue
            if (h, w) != (im["height"], im["width"]):
                r["problems"].append(f"{im_file}: {w}x{h}, COCO says {im['width']}x{im['height']}")
            expected = anns.get(im["id"], [])
            if len(expected) != len(segments):
                r["problems"].append(f"{lb_file}: {len(segments)} lines for {len(expected)} instances")
                continue
            idmap_rgb = np.array(Image.open(os.path.join(image_root, im["mask_file"])).convert("RGB")).astype(np.int64)
            building = (idmap_rgb[..., 0] << 16) | (idmap_rgb[..., 1] << 8) | idmap_rgb[..., 2]
            for a, seg in zip(expected, segments):
                poly = seg.astype(np.float64) * np.array([w, h])
                filled = even_odd_fill(poly, h, w)
                seg_json = a.get("mask_rle") or a["segmentation"]
                ref = mask_utils.decode(seg_json).astype(bool)
                if not np.all(building[ref] == a["building_id"]):
                    r["problems"].append(f"annotation {a['id']}: instance mask is not its building in the ID map")
                iou = float((filled & ref).sum() / max(1, (filled | ref).sum()))
                r["min_iou"] = min(r["min_iou"], iou)
                r["instances"] += 1
                r["max_vertices"] = max(r["max_vertices"], len(seg))
        out["splits"][split] = r
    print(json.dumps(out))


def hf(coco_dir):
    import shutil
    import tempfile

    # A local folder: nothing to fetch, and a cache of its own that goes with this check.
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    cache = tempfile.mkdtemp(prefix="insgen-hf-cache-")
    try:
        _hf(coco_dir, cache)
    finally:
        shutil.rmtree(cache, ignore_errors=True)


def _hf(coco_dir, cache):
    import datasets
    from pycocotools import mask as mask_utils

    # The folder alone, as a user on another machine would load it: no loader name, no data_dir.
    ds = datasets.load_dataset(os.path.abspath(coco_dir), cache_dir=cache)
    out = {
        "datasets": datasets.__version__,
        "loaded_splits": sorted(ds.keys()),
        "columns": {k: sorted(v.column_names) for k, v in ds.items()},
        "splits": {},
    }
    for split, hf_split in (("train", "train"), ("val", "validation"), ("test", "test")):
        with open(os.path.join(coco_dir, f"instances_{split}.json")) as f:
            inst = json.load(f)
        anns = {}
        for a in inst["annotations"]:
            anns.setdefault(a["image_id"], []).append(a)
        images = {im["id"]: im for im in inst["images"]}
        r = {"coco_images": len(images), "rows": 0, "objects": 0, "decoded": 0, "problems": []}
        out["splits"][split] = r
        if hf_split not in ds:
            continue
        for row in ds[hf_split]:
            r["rows"] += 1
            im = images.get(row["image_id"])
            if im is None:
                r["problems"].append(f"row of image {row['image_id']}: not in instances_{split}.json")
                continue
            photo = row["image"]
            photo.load()
            r["decoded"] += 1
            if photo.size != (im["width"], im["height"]):
                r["problems"].append(f"image {im['id']}: {photo.size}, COCO says {im['width']}x{im['height']}")
            if (row["area_name"], row["camera"], row["frame"]) != (im["area_name"], im["camera"], im["frame"]):
                r["problems"].append(f"image {im['id']}: other area, camera or frame")
            o = row["objects"]
            expected = anns.get(im["id"], [])
            if o["id"] != [a["id"] for a in expected]:
                r["problems"].append(f"image {im['id']}: objects {o['id']}, COCO {[a['id'] for a in expected]}")
                continue
            for k, a in enumerate(expected):
                for key in ("bbox", "category_id", "area", "iscrowd", "building_id"):
                    if o[key][k] != a[key]:
                        r["problems"].append(f"annotation {a['id']}: {key} {o[key][k]} != {a[key]}")
                seg = o["segmentation"][k]
                got = mask_utils.decode({"size": seg["size"], "counts": seg["counts"].encode()})
                ref_json = a.get("mask_rle") or a["segmentation"]
                if isinstance(ref_json["counts"], list):
                    ref_json = mask_utils.frPyObjects(ref_json, *ref_json["size"])
                ref = mask_utils.decode(ref_json)
                if not np.array_equal(got, ref):
                    r["problems"].append(f"annotation {a['id']}: mask differs in {int((got != ref).sum())} px")
                r["objects"] += 1
    print(json.dumps(out))


if __name__ == "__main__":
    cmd, args = sys.argv[1], sys.argv[2:]
    {"colmap": colmap, "panoptic": panoptic, "yolo": yolo, "hf": hf}[cmd](*args)
