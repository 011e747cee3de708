"""Training loops of the two families, checkpoints, and prediction of one frame."""

from __future__ import annotations

import hashlib
import io
import json
import math
import signal
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

import data as ds
import instances as inst
import models

LEVELS_MULTIPLE = 16  # the U-Net pools 4 times
WARMUP_STEPS = 20  # linear learning-rate warm-up, then a cosine decay over the step or time budget


# --------------------------------------------------------------------------------------------- batches
class UnetBatches:
    """Random crops of the frames with their targets, flipped left-right at random, colour-jittered.

    The frames and their targets live on the training device (padded to the largest frame, padding
    ignored in the loss), so a batch is cut there: no per-step copies from the host. Random draws come
    from one seeded CPU generator, so a seed gives the same batches on any device.
    """

    def __init__(self, frames: list[ds.Frame], crop_hw: tuple[int, int], rim_px: int, seed: int, dev):
        self.gen = torch.Generator().manual_seed(seed)
        self.dev = dev
        n = len(frames)
        h_max = max(f.rgb.shape[0] for f in frames)
        w_max = max(f.rgb.shape[1] for f in frames)
        ch, cw = min(crop_hw[0], h_max), min(crop_hw[1], w_max)
        self.crop = (max(LEVELS_MULTIPLE, ch - ch % LEVELS_MULTIPLE), max(LEVELS_MULTIPLE, cw - cw % LEVELS_MULTIPLE))
        rgb = torch.zeros((n, 3, h_max, w_max), dtype=torch.uint8)
        cls = torch.full((n, h_max, w_max), ds.IGNORE, dtype=torch.uint8)
        touch = torch.zeros((n, h_max, w_max), dtype=torch.bool)
        dist = torch.zeros((n, h_max, w_max), dtype=torch.float16)
        self.sizes = []
        for i, f in enumerate(frames):
            c, t, d = ds.unet_targets(f.instances, f.ignore, rim_px)
            h, w = c.shape
            rgb[i, :, :h, :w] = torch.from_numpy(np.ascontiguousarray(f.rgb.transpose(2, 0, 1)))
            cls[i, :h, :w] = torch.from_numpy(c)
            touch[i, :h, :w] = torch.from_numpy(t)
            dist[i, :h, :w] = torch.from_numpy(d)
            self.sizes.append((h, w))
        self.rgb, self.cls, self.touch, self.dist = (t.to(dev) for t in (rgb, cls, touch, dist))

    def sample(self, batch: int):
        ch, cw = self.crop
        g = self.gen
        idx = torch.randint(len(self.sizes), (batch,), generator=g).tolist()
        xs, cls, tch, dst = [], [], [], []
        for i in idx:
            h, w = self.sizes[i]
            y0 = int(torch.randint(max(h - ch, 0) + 1, (1,), generator=g))
            x0 = int(torch.randint(max(w - cw, 0) + 1, (1,), generator=g))
            sl = (i, slice(y0, y0 + ch), slice(x0, x0 + cw))
            xs.append(self.rgb[i, :, y0:y0 + ch, x0:x0 + cw])
            cls.append(self.cls[sl])
            tch.append(self.touch[sl])
            dst.append(self.dist[sl])
        flip = (torch.rand(batch, generator=g) < 0.5).to(self.dev)
        contrast = torch.empty(batch, 1, 1, 1).uniform_(0.8, 1.2, generator=g).to(self.dev)
        bright = torch.empty(batch, 1, 1, 1).uniform_(-0.08, 0.08, generator=g).to(self.dev)
        gain = torch.empty(batch, 3, 1, 1).uniform_(0.75, 1.25, generator=g).to(self.dev)
        x = torch.stack(xs).float().div_(255)
        x = ((x - 0.5) * contrast + 0.5 + bright).clamp_(0, 1) * gain
        c, t, d = torch.stack(cls), torch.stack(tch), torch.stack(dst)
        x = torch.where(flip[:, None, None, None], x.flip(-1), x)
        c, t, d = (torch.where(flip[:, None, None], v.flip(-1), v) for v in (c, t, d))
        return x, c.long(), t, d.float()


def unet_loss(out: torch.Tensor, cls: torch.Tensor, touching: torch.Tensor, dist: torch.Tensor,
              touch_weight: float) -> tuple[torch.Tensor, dict]:
    logits, dist_logit = out[:, :3].float(), out[:, 3].float()
    ce = F.cross_entropy(logits, cls, ignore_index=ds.IGNORE, reduction="none")
    valid = (cls != ds.IGNORE).float()
    weight = valid * (1.0 + (touch_weight - 1.0) * touching.float())
    ce_loss = (ce * weight).sum() / weight.sum().clamp(min=1.0)
    fg = ((cls == ds.INTERIOR) | (cls == ds.RIM)).float()
    dist_err = (torch.sigmoid(dist_logit) - dist) ** 2
    dist_loss = (dist_err * fg).sum() / fg.sum().clamp(min=1.0)
    loss = ce_loss + 2.0 * dist_loss
    return loss, {"ce": float(ce_loss.detach()), "dist": float(dist_loss.detach())}


class RcnnBatches:
    """Whole frames (flipped at random) with per-instance boxes and masks, for Mask R-CNN."""

    def __init__(self, frames: list[ds.Frame], seed: int):
        self.gen = torch.Generator().manual_seed(seed)
        self.frames = frames

    def sample(self, batch: int, dev):
        images, targets = [], []
        for _ in range(batch):
            f = self.frames[int(torch.randint(len(self.frames), (1,), generator=self.gen))]
            rgb, ids = f.rgb, f.instances
            if float(torch.rand(1, generator=self.gen)) < 0.5:
                rgb, ids = rgb[:, ::-1], ids[:, ::-1]
            labels = [k for k in np.unique(ids) if k > 0]
            masks = np.stack([ids == k for k in labels]).astype(np.uint8)
            boxes = []
            for m in masks:
                ys, xs = np.nonzero(m)
                boxes.append([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1])
            images.append(torch.from_numpy(np.ascontiguousarray(rgb.transpose(2, 0, 1))).float().div(255).to(dev))
            targets.append({"boxes": torch.tensor(boxes, dtype=torch.float32, device=dev),
                            "labels": torch.ones(len(labels), dtype=torch.int64, device=dev),
                            "masks": torch.from_numpy(masks).to(dev)})
        return images, targets


# ------------------------------------------------------------------------------------------------ train
def train(args, frames: list[ds.Frame], dev, log) -> None:
    """Trains until the step or time budget ends (or Ctrl-C: checkpoint, then exit 130)."""
    crop = tuple(int(v) for v in args.crop.lower().split("x"))
    size = frames[0].rgb.shape[:2]
    model = models.build(args.family, args.width, size).to(dev)
    if args.family == "unet":
        model = model.to(memory_format=torch.channels_last)  # ≈ 30 % faster convolutions on CPU and GPU
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    batches = (UnetBatches(frames, crop, args.rim_px, args.seed, dev) if args.family == "unet"
               else RcnnBatches(frames, args.seed))
    meta = {"family": args.family, "width": args.width, "scale": args.scale, "image_size": list(size),
            "rim_px": args.rim_px, "touch_weight": args.touch_weight, "seed": args.seed, "lr": args.lr,
            "batch": args.batch, "frames": len(frames), "coco": str(args.coco)}
    run = Run(args, model, opt, batches, meta, dev, log)
    # Ctrl-C (or SIGTERM from a scheduler) ends the run between two steps, with a checkpoint of a
    # consistent state: --resume then continues exactly where it stopped.
    previous = {sig: signal.signal(sig, run.request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        run.loop()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if run.stop_requested:
        run.save()
        log(f"stopped at step {run.step}; checkpoint {run.ckpt_path} (continue with --resume)")
        raise SystemExit(130)
    run.finish()


class Run:
    """One training run's state: what a checkpoint holds, so that --resume continues the same course."""

    def __init__(self, args, model, opt, batches, meta, dev, log):
        self.args, self.model, self.opt, self.batches, self.meta, self.dev, self.log = (
            args, model, opt, batches, meta, dev, log)
        self.ckpt_path = args.out / "checkpoint.pt"
        self.step, spent_s = 0, 0.0
        args.out.mkdir(parents=True, exist_ok=True)
        if args.resume and self.ckpt_path.exists():
            state = torch.load(self.ckpt_path, map_location=dev, weights_only=False)
            model.load_state_dict(state["model"])
            opt.load_state_dict(state["optimizer"])
            batches.gen.set_state(state["rng"])
            self.step, spent_s = state["meta"]["steps"], state["meta"]["train_seconds"]
            self.first_loss = state["meta"].get("first_loss")
            log(f"resumed from {self.ckpt_path} at step {self.step}")
        self.t0 = time.time() - spent_s
        self.losses: list[float] = []
        self.first_loss = None
        self.stop_requested = False

    def request_stop(self, *_signal) -> None:
        self.stop_requested = True

    def loop(self) -> None:
        args, dev = self.args, self.dev
        budget_s = args.minutes * 60.0 if args.minutes else math.inf
        last_log = last_ckpt = time.time()
        self.model.train()
        while self.step < args.steps and time.time() - self.t0 < budget_s and not self.stop_requested:
            progress = max(self.step / args.steps, (time.time() - self.t0) / budget_s)
            warm = min(1.0, (self.step + 1) / WARMUP_STEPS)
            lr = args.lr * warm * 0.5 * (1 + math.cos(math.pi * min(progress, 1.0)))
            for g in self.opt.param_groups:
                g["lr"] = lr
            with torch.autocast(device_type=dev.type, dtype=torch.bfloat16, enabled=dev.type == "cuda"):
                loss, parts = one_step(self.model, self.batches, args, dev)
            self.opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.model.parameters(), 5.0)
            self.opt.step()
            self.step += 1
            self.losses.append(float(loss.detach()))
            if self.first_loss is None:
                self.first_loss = self.losses[0]
            now = time.time()
            if now - last_log >= args.log_every or self.step == args.steps:
                self.progress_line(lr, parts, now)
                last_log = now
            if now - last_ckpt >= args.checkpoint_every:
                self.save()
                last_ckpt = now

    def progress_line(self, lr: float, parts: dict, now: float) -> None:
        line = {"step": self.step, "loss": float(np.mean(self.losses[-20:])), "lr": lr,
                "seconds": round(now - self.t0, 1), **parts}
        with (self.args.out / "train_log.jsonl").open("a") as fh:
            fh.write(json.dumps(line) + "\n")
        rate = self.step / max(now - self.t0, 1e-9)
        self.log(f"step {self.step} loss {line['loss']:.4f} lr {lr:.2e} {rate:.2f} steps/s {now - self.t0:.0f} s")

    def save(self, meta: dict | None = None) -> None:
        meta = meta or {**self.meta, "steps": self.step, "train_seconds": round(time.time() - self.t0, 1),
                        "first_loss": self.first_loss}
        save_checkpoint(self.ckpt_path, self.model, self.opt, meta, self.batches.gen.get_state())

    def finish(self) -> None:
        seconds = time.time() - self.t0
        final = {**self.meta, "steps": self.step, "train_seconds": round(seconds, 1), "device": str(self.dev),
                 "first_loss": self.first_loss,
                 "final_loss": float(np.mean(self.losses[-20:])) if self.losses else None,
                 "weights_sha256": weights_digest(self.model)}
        self.save(final)
        tmp = self.args.out / "model.json.tmp"
        tmp.write_text(json.dumps(final, indent=2) + "\n")
        tmp.replace(self.args.out / "model.json")
        self.log(f"trained {self.step} steps in {seconds:.0f} s; loss {self.first_loss} → {final['final_loss']}; "
                 f"wrote {self.ckpt_path}")


def one_step(model, batches, args, dev):
    if args.family == "unet":
        x, cls, touching, dist = batches.sample(args.batch)
        x = x.contiguous(memory_format=torch.channels_last)
        return unet_loss(model(x), cls, touching, dist, args.touch_weight)
    images, targets = batches.sample(args.batch, dev)
    parts = model(images, targets)
    loss = sum(parts.values())
    return loss, {k: float(v.detach()) for k, v in parts.items()}


def weights_digest(model) -> str:
    """SHA-256 of the weights (every state-dict tensor's bytes, in key order): equal for equal training."""
    h = hashlib.sha256()
    for k, v in sorted(model.state_dict().items()):
        h.update(k.encode())
        h.update(v.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def save_checkpoint(path: Path, model, opt, meta: dict, rng_state: torch.Tensor) -> None:
    """Weights, optimizer, the batch generator's state and `meta` (temporary file + rename)."""
    buf = io.BytesIO()
    torch.save({"model": model.state_dict(), "optimizer": opt.state_dict(), "rng": rng_state, "meta": meta}, buf)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(buf.getvalue())
    tmp.replace(path)


def load_checkpoint(path: Path, dev):
    try:
        state = torch.load(path, map_location=dev, weights_only=False)
    except FileNotFoundError as e:
        raise ds.DataError(f"{path}: no such checkpoint (run `baseline.py train`)") from e
    meta = state["meta"]
    model = models.build(meta["family"], meta["width"], tuple(meta["image_size"])).to(dev)
    model.load_state_dict(state["model"])
    if meta["family"] == "unet":
        model = model.to(memory_format=torch.channels_last)
    model.eval()
    return model, meta


# ---------------------------------------------------------------------------------------------- predict
@torch.no_grad()
def predict_frame(model, meta: dict, frame: ds.Frame, dev, tta: bool = True, min_area_px: int = 16):
    """Instances `(mask at native size, score)` of one frame."""
    x = torch.from_numpy(np.ascontiguousarray(frame.rgb.transpose(2, 0, 1))).float().div(255).to(dev)
    native = (frame.height_px, frame.width_px)
    if meta["family"] == "maskrcnn":
        out = model([x])[0]
        masks = F.interpolate(out["masks"].float(), size=native, mode="bilinear", align_corners=False)
        return [(m[0].cpu().numpy() > 0.5, float(s)) for m, s in zip(masks, out["scores"])
                if (m[0] > 0.5).sum() >= min_area_px]
    probs, dist = unet_maps(model, x, dev, tta)
    probs = F.interpolate(probs[None], size=native, mode="bilinear", align_corners=False)[0]
    dist = F.interpolate(dist[None, None], size=native, mode="bilinear", align_corners=False)[0, 0]
    return inst.decode_unet(probs.cpu().numpy(), dist.cpu().numpy(), min_area_px=min_area_px)


def unet_maps(model, x: torch.Tensor, dev, tta: bool):
    """Class probabilities (3, h, w) and distance (h, w), averaged with the mirrored image when `tta`."""
    xp, (h, w) = models.pad_to(x[None], LEVELS_MULTIPLE)
    batch = (torch.cat([xp, xp.flip(-1)]) if tta else xp).contiguous(memory_format=torch.channels_last)
    with torch.autocast(device_type=dev.type, dtype=torch.bfloat16, enabled=dev.type == "cuda"):
        out = model(batch).float()
    if tta:
        out = 0.5 * (out[0] + out[1].flip(-1))
    else:
        out = out[0]
    out = out[:, :h, :w]
    return torch.softmax(out[:3], dim=0), torch.sigmoid(out[3])
