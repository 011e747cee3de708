#!/usr/bin/env python3
"""insgen's reference baseline: an instance segmenter trained from scratch on an insgen COCO export.

  train    --coco DIR --out DIR [--family unet|maskrcnn] [--steps N] [--minutes M] [--device auto|cpu|cuda]
           trains on instances_<split>.json (default train), writes DIR/checkpoint.pt (every
           --checkpoint-every seconds and at the end, temp file + rename), DIR/train_log.jsonl and
           DIR/model.json; --resume continues from DIR/checkpoint.pt
  predict  --checkpoint FILE --coco FILE.json --out RESULTS.json [--area NAME]
           a COCO results file (compressed RLE, bbox, score) that pycocotools and `insgen eval-loc
           --predictions` read
  score    --coco FILE.json --results RESULTS.json [--area NAME] [--out SCORE.json]
           pycocotools COCOeval (segm: AP, AP50, AP75), building-pixel IoU, precision/recall at IoU 0.5
  sheet    --coco FILE.json --results RESULTS.json --out SHEET.png [--area NAME] [--count N]
           rows of RGB | truth | prediction | building pixels missed (red) and extra (blue)
  pack     --coco DIR --out DIR [--quality Q]
           a compact, self-contained copy of an export (JPEG photos, annotations as they are) to train
           on another machine, e.g. a GPU machine that takes a few tens of MB

Nothing is downloaded: both families start from random weights. Same data, seed and --steps on the same
device give the same checkpoint; a --minutes budget stops on the clock, so its step count varies.
Training and prediction need torch, torchvision, numpy, scipy, scikit-image and pillow (RLE in numpy,
rle.py); scoring, pictures and polygon annotations also pycocotools (scripts/setup_train.sh installs all).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import data as ds  # noqa: E402
import instances as inst  # noqa: E402


def log(msg: str) -> None:
    print(f"[baseline] {msg}", file=sys.stderr, flush=True)


def write_atomic(path: Path, payload: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(payload)
    os.replace(tmp, path)


def pick_device(name: str):
    import torch

    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise SystemExit("baseline: --device cuda but torch sees no CUDA device (torch "
                         f"{torch.__version__}); use --device cpu or auto")
    dev = torch.device(name)
    what = torch.cuda.get_device_name(0) if name == "cuda" else f"CPU, {torch.get_num_threads()} threads"
    log(f"device: {name} ({what}), torch {torch.__version__}")
    return dev


def coco_file(path: Path, split: str) -> Path:
    return path / f"instances_{split}.json" if path.is_dir() else path


# ------------------------------------------------------------------------------------------------ train
def cmd_train(args) -> None:
    import torch

    import trainer

    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    dev = pick_device(args.device)
    frames = []
    sources = [coco_file(args.coco, s) for s in (args.split or ["train"])] if args.coco.is_dir() else [args.coco]
    for src in sources:
        if args.coco.is_dir() and not src.exists():
            log(f"no {src.name} in {args.coco}: skipped")
            continue
        frames += ds.load_split(src, args.area or None, args.scale, args.limit)[1]
    frames = [f for f in frames if (f.instances > 0).any()]
    src = ", ".join(str(s) for s in sources)
    if not frames:
        raise SystemExit(f"baseline: {src}: no image with an annotation to train on (areas: "
                         f"{args.area or 'all'}); export a dataset with buildings in view")
    log(f"{len(frames)} training frames from {src} (scale {args.scale})")
    trainer.train(args, frames, dev, log)


# ---------------------------------------------------------------------------------------------- predict
def cmd_predict(args) -> None:
    import trainer

    dev = pick_device(args.device)
    model, meta = trainer.load_checkpoint(args.checkpoint, dev)
    _, frames = ds.load_split(args.coco, args.area or None, meta["scale"], args.limit)
    if not frames:
        raise SystemExit(f"baseline: {args.coco}: no image to predict (areas: {args.area or 'all'})")
    results = []
    t0 = time.time()
    for i, f in enumerate(frames):
        found = trainer.predict_frame(model, meta, f, dev, tta=not args.no_tta, min_area_px=args.min_area)
        results.extend(inst.result_entries(f.image_id, found))
        if (i + 1) % 20 == 0 or i + 1 == len(frames):
            log(f"predicted {i + 1}/{len(frames)} frames, {len(results)} instances, "
                f"{(time.time() - t0) / (i + 1):.2f} s/frame")
    write_atomic(args.out, json.dumps(results).encode())
    log(f"wrote {args.out} ({len(results)} instances on {len(frames)} images)")


# ------------------------------------------------------------------------------------------------ score
def cmd_score(args) -> None:
    import scoring

    report = scoring.score(args.coco, args.results, args.area or None)
    text = json.dumps(report, indent=2)
    if args.out:
        write_atomic(args.out, (text + "\n").encode())
    print(text)


def cmd_sheet(args) -> None:
    import scoring

    scoring.sheet(args.coco, args.results, args.out, args.area or None, args.count, args.min_score)
    log(f"wrote {args.out}")


def cmd_pack(args) -> None:
    """A self-contained, compact copy of an export for training elsewhere (e.g. a GPU machine with a
    size limit on what travels): the instances files with `info.image_root` "." and every photo as a
    JPEG under images/ (quality --quality), annotations unchanged."""
    from PIL import Image

    out = args.out
    (out / "images").mkdir(parents=True, exist_ok=True)
    total = 0
    for split in args.split or ["train", "val", "test"]:
        src = coco_file(args.coco, split)
        if not src.exists():
            log(f"no {src}: skipped")
            continue
        data = json.loads(src.read_text())
        root = src.parent / data.get("info", {}).get("image_root", ".")
        for im in data["images"]:
            name = f"images/{split}_{im['id']:06d}.jpg"
            dest = out / name
            if not dest.exists():
                tmp = dest.with_name(dest.name + ".tmp.jpg")
                try:
                    Image.open(root / im["file_name"]).convert("RGB").save(tmp, quality=args.quality)
                except (FileNotFoundError, OSError) as e:
                    raise ds.DataError(f"{root / im['file_name']}: cannot read image {im['id']}: {e}") from e
                os.replace(tmp, dest)
            im["file_name"] = name
            for key in ("mask_file", "ignore_file"):
                im.pop(key, None)  # the pack carries the annotations, not the ID maps
        data.setdefault("info", {})["image_root"] = "."
        write_atomic(out / src.name, json.dumps(data).encode())
        total += len(data["images"])
    size_mb = sum(f.stat().st_size for f in out.rglob("*") if f.is_file()) / 1e6
    log(f"packed {total} images into {out} ({size_mb:.1f} MB)")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="train from scratch on an insgen COCO export")
    t.add_argument("--coco", type=Path, required=True, help="export folder or instances_<split>.json")
    t.add_argument("--split", action="append",
                   help="split(s) to train on, repeat (default: train); with a folder for --coco")
    t.add_argument("--area", action="append", help="train on these areas only (repeat)")
    t.add_argument("--out", type=Path, required=True, help="model folder (checkpoint, logs)")
    t.add_argument("--family", choices=("unet", "maskrcnn"), default="unet")
    t.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto")
    t.add_argument("--steps", type=int, default=100_000, help="step budget")
    t.add_argument("--minutes", type=float, default=None, help="time budget (stops on the clock)")
    t.add_argument("--batch", type=int, default=16)
    t.add_argument("--width", type=int, default=32, help="U-Net base channels")
    t.add_argument("--crop", type=str, default="352x640", help="training crop HxW (U-Net)")
    t.add_argument("--scale", type=float, default=1.0, help="resize frames by this before training")
    t.add_argument("--lr", type=float, default=2e-3)
    t.add_argument("--touch-weight", type=float, default=6.0,
                   help="loss weight of rim pixels where two buildings touch")
    t.add_argument("--rim-px", type=int, default=1, help="rim width in pixels at the training scale")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--limit", type=int, default=None, help="use the first N images only")
    t.add_argument("--log-every", type=float, default=30.0, help="seconds between progress lines")
    t.add_argument("--checkpoint-every", type=float, default=300.0, help="seconds between checkpoints")
    t.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    t.set_defaults(func=cmd_train)
    q = sub.add_parser("predict", help="COCO results file for one instances file")
    q.add_argument("--checkpoint", type=Path, required=True)
    q.add_argument("--coco", type=Path, required=True, help="instances_<split>.json")
    q.add_argument("--area", action="append")
    q.add_argument("--out", type=Path, required=True)
    q.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto")
    q.add_argument("--no-tta", action="store_true", help="skip averaging with the mirrored image")
    q.add_argument("--min-area", type=int, default=16, help="smallest instance kept, px")
    q.add_argument("--limit", type=int, default=None)
    q.set_defaults(func=cmd_predict)
    s = sub.add_parser("score", help="pycocotools segm AP, building IoU, P/R at IoU 0.5")
    s.add_argument("--coco", type=Path, required=True)
    s.add_argument("--results", type=Path, required=True)
    s.add_argument("--area", action="append")
    s.add_argument("--out", type=Path)
    s.set_defaults(func=cmd_score)
    c = sub.add_parser("sheet", help="picture: RGB | truth | prediction")
    c.add_argument("--coco", type=Path, required=True)
    c.add_argument("--results", type=Path, required=True)
    c.add_argument("--out", type=Path, required=True)
    c.add_argument("--area", action="append")
    c.add_argument("--count", type=int, default=6)
    c.add_argument("--min-score", type=float, default=0.3)
    c.set_defaults(func=cmd_sheet)
    k = sub.add_parser("pack", help="a compact self-contained copy of an export (JPEG photos) to train elsewhere")
    k.add_argument("--coco", type=Path, required=True, help="export folder")
    k.add_argument("--out", type=Path, required=True)
    k.add_argument("--split", action="append", help="splits to pack (default: train, val, test)")
    k.add_argument("--quality", type=int, default=95, help="JPEG quality")
    k.set_defaults(func=cmd_pack)
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        args.func(args)
    except ds.DataError as e:
        print(f"baseline: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
