#!/usr/bin/env python3
"""Writes one run's section of bench/closed_loop.md from a closed-loop work directory.

Reads `<workdir>/loop.json` (what scripts/bench_closed_loop.sh ran), each family's `model.json`,
`score_<holdout>.json` and `score_val.json` (the mask zoom the calibration undoes), and eval-loc's
`summary.json` of the oracle and prediction runs, as predicted and calibrated (and the calibrated run's
`results.jsonl`, set against each held-out frame's outline F1, which `scoring.py` computes); copies each
family's picture next to the report. The section sits between `<!-- run:LABEL -->` markers, so runs of
other sizes (the CPU run, a GPU run) stay in the file.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from PIL import Image

HEADER = """# The closed loop: dataset → model → predictions → pycocotools and eval-loc

Each section is one run of `scripts/bench_closed_loop.sh`: insgen renders a dataset (masks + Blender RGB)
of the training areas, holds one area out entirely (its buildings, city and CRS are never seen in
training), trains the reference baseline (`scripts/train/baseline.py`) from scratch on the rest, predicts
the held-out frames, scores them with pycocotools (COCOeval segm against insgen's own COCO export) and
localizes them with `insgen eval-loc --predictions` next to the oracle (ground-truth) masks. Definitions:
AP/AP50/AP75 are COCOeval's; building IoU is the IoU of the union of predicted masks (score ≥ 0.3)
with the union of true ones; P/R@0.5 are one-to-one matches at mask IoU ≥ 0.5; outline F1 is the
F-score of the predicted and true building outlines within 1 and 2 px; mask zoom is the scale about the
principal point that fits the true masks best to the predicted ones (median over the frames; above 1 the
masks reach past the buildings, which eval-loc reads as a camera moved forward).
Localization recall is the share of queries within (2 m, 2°) of the truth; the oracle rows are the upper
bound the masks allow; the calibrated rows undo the mask zoom measured on the validation split, or on
a calibration area neither trained on nor held out where the run names one (`--calibrate`;
`eval-loc --prediction-zoom`), so no held-out frame informs them. The score rank correlation is
`score_honesty`'s: how well the predictions' scores rank their masks (Spearman, against each mask's best
IoU with a true instance); where the validation split finds them honest, the loop also weights the
instances by box area × score (`eval-loc --weighting area-conf`). The loop's photos are rendered from
the map, so the map is as detailed as what they show; there the grouped cost keeps its groups in the
polish's second pass (`--polish-semantic-weight 0`) rather than the union's outline, the default made
for maps coarser than the photos (bench/loc_learned.md).
"""


def honesty(score: dict) -> str:
    """The scores' Spearman correlation with the masks' IoU, marked when `baseline.py score` finds them honest."""
    h = score.get("score_honesty") or {}
    if h.get("spearman") is None:
        return "–"
    return f"{h['spearman']}{' (honest)' if h.get('honest') else ''}"


def load(path: Path):
    return json.loads(path.read_text()) if path.exists() else None


def loc_rows(summary: dict | None, source: str, prior: bool = True) -> list[str]:
    if not summary:
        return [f"| {source} | (not run) | | | | |"]
    rows = []
    groups = {r["group"] for r in summary["rows"]}
    # The signed depth error (eval-loc's axis rows; absent for the prior and in older summaries): a
    # median far from 0 with most estimates on one side is a bias of the masks, not noise.
    axis = {a["method"]: a for a in summary.get("axis_rows", [])}
    for r in summary["rows"]:
        if (len(groups) > 1 and r["group"] != "all") or (not prior and r["method"] == "prior"):
            continue
        rec = r["recall_pct"][0]
        t, q = r["median_translation_m"], r["median_rotation_deg"]
        a = axis.get(r["method"], {})
        signed = a.get("median_axial_m")
        depth = "–" if signed is None else f"{signed:+.2f} m ({a.get('estimates_ahead', 0)} of {a['queries']})"
        rows.append(f"| {source} | {r['method']} | {rec:.1f} % | {fmt(t, 'm')} | {fmt(q, '°')} | {depth} |")
    return rows


OUTLINE_BANDS = ((0.0, 0.4), (0.4, 0.5), (0.5, 0.6), (0.6, 1.01))


def localized(r: dict) -> bool:
    """Whether an eval-loc result lies within (2 m, 2°) of the truth."""
    return r["translation_error_m"] < 2 and r["rotation_error_deg"] < 2


def by_outline_band(rows: list[dict], f1: dict) -> tuple[list[str], list[tuple]]:
    """eval-loc's results per band of their frame's outline F1 (`f1`, by frame name; OUTLINE_BANDS): the
    costs, and per band (lo, hi, frames, {cost: (localized, queries)})."""
    costs = list(dict.fromkeys(r["cost"] for r in rows))
    bands = []
    for lo, hi in OUTLINE_BANDS:
        inside = [r for r in rows if f1.get(r["name"]) is not None and lo <= f1[r["name"]] < hi]
        counts = {}
        for c in costs:
            rs = [r for r in inside if r["cost"] == c]
            counts[c] = (sum(map(localized, rs)), len(rs))
        bands.append((lo, hi, len({r["name"] for r in inside}), counts))
    return costs, bands


def outline_rows(w: Path, loop: dict, first: str) -> list[str]:
    """Recall of the calibrated held-out queries (defaults) per band of their frame's outline F1 at 1 px."""
    hold, cam = loop["holdout"], loop["camera"]
    results = w / hold / cam / "loc" / f"loop-{first}-defaults-calibrated" / "results.jsonl"
    preds = w / "model" / first / f"results_{hold}.json"
    if not results.exists() or not preds.exists():
        return []
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import scoring  # the training environment's; only the report needs it

    f1 = scoring.outline_f1_per_frame(w / "coco" / "instances_test.json", preds, [hold])
    rows = [json.loads(line) for line in results.read_text().splitlines() if line.strip()]
    costs, bands = by_outline_band(rows, f1)
    out = [f"Recall at (2 m, 2°) of the calibrated queries (defaults) by how well `{first}` drew the frame's "
           "building outlines (`outline_f1` within 1 px, per frame): where the masks' edges are off, the pose "
           "is.", "", "| outline F1 | frames | " + " | ".join(costs) + " |", "|---|---:|" + "---:|" * len(costs)]
    for lo, hi, frames, counts in bands:
        cells = [f"{100 * ok / n:.1f} % ({ok} of {n})" if n else "–" for ok, n in counts.values()]
        band = f"< {hi}" if lo == 0 else (f"≥ {lo}" if hi > 1 else f"{lo}–{hi}")
        out.append(f"| {band} | {frames} | " + " | ".join(cells) + " |")
    return out + [""]


def fmt(v, unit):
    return "–" if v is None else f"{v:.2f} {unit}"


def learnability_rows(stats: dict | None) -> list[str]:
    """Per area: what predicts instance learnability (insgen stats; definitions in coco/stats.md)."""
    if not stats:
        return []
    out = ["What the data asks of the model, per area (`insgen stats`, learnability block): touching boundary per "
           "image, share of instances touching another, colour contrast across touching vs background "
           "boundaries (0–255 levels), median instance area, share under 32² px, share of buildings split by "
           "occluders.", "",
           "| area | split | images | touching px / image | touching instances | contrast touching / background |"
           " median area px | small | split by occluders |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for a in stats.get("areas", []):
        ln = a.get("learnability", {})
        b, c, s, o = ln.get("boundary", {}), ln.get("contrast"), ln.get("sizes", {}), ln.get("occluder_splits", {})
        contrast = (f"{c['touching_rgb_levels']:.1f} / {c['background_rgb_levels']:.1f}" if c else "–")
        out.append(f"| {a['area']} | {a['split']} | {a['images']} | {b.get('touching_px_per_image', 0):.0f} | "
                   f"{100 * b.get('touching_instances_share', 0):.0f} % | {contrast} | {s.get('area_p50_px', '–')} | "
                   f"{100 * s.get('small_share', 0):.0f} % | {100 * o.get('split_share', 0):.1f} % |")
    return out + [""]


def section(w: Path, bench: Path) -> str:
    loop = load(w / "loop.json")
    if loop is None:
        sys.exit(f"loop_report: {w}/loop.json missing (run scripts/bench_closed_loop.sh first)")
    hold, cam, label = loop["holdout"], loop["camera"], loop["label"]
    cal = None if loop.get("calibration", "val") == "val" else loop["calibration"]
    out = [f"<!-- run:{label} -->", f"## Run `{label}`: held out `{hold}`, trained on {loop['train_areas']}", "",
           f"Reproduce: `{loop['command']}` ({cam}, {loop['frames_per_area']} frames per training area, "
           f"{loop['holdout_frames']} held-out frames, {loop['queries']} localization queries).", "",
           "| family | device | steps | train s | train frames | AP | AP50 | AP75 | building IoU | P@0.5 | R@0.5 |"
           " predictions / truths | outline F1 (1 / 2 px) | mask zoom (validation / held out"
           f"{' / calibration area ' + cal if cal else ''}) |"
           " score rank correlation (validation / held out) |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    pictures = []
    for fam in loop["families"].split():
        m = load(w / "model" / fam / "model.json") or {}
        s = load(w / "model" / fam / f"score_{hold}.json") or {}
        v = load(w / "model" / fam / "score_val.json") or {}
        c = load(w / "model" / fam / "score_calibration.json") or {} if cal else None
        zooms = " / ".join(str((x.get("mask_zoom") or {}).get("median") or "–") for x in (v, s, c) if x is not None)
        ranks = " / ".join(honesty(x) for x in (v, s))
        outlines = " / ".join(str(v) for v in (s.get("outline_f1") or {"1px": "–", "2px": "–"}).values())
        out.append(f"| {fam} | {m.get('device', '–')} | {m.get('steps', '–')} | {m.get('train_seconds', '–')} | "
                   f"{m.get('frames', '–')} | {s.get('AP', '–')} | {s.get('AP50', '–')} | {s.get('AP75', '–')} | "
                   f"{s.get('building_iou', '–')} | {s.get('precision_50', '–')} | {s.get('recall_50', '–')} | "
                   f"{s.get('predictions', '–')} / {s.get('annotations', '–')} | {outlines} | {zooms} | {ranks} |")
        sheet = w / "model" / fam / f"sheet_{hold}.png"
        if sheet.exists():
            # A JPEG next to the report: the PNG sheet runs to megabytes.
            dest = bench / f"closed_loop_{label}_{fam}.jpg"
            tmp = dest.with_name(dest.name + ".tmp.jpg")
            Image.open(sheet).convert("RGB").save(tmp, quality=85)
            tmp.replace(dest)
            pictures.append((fam, dest.name))
    out += [""] + learnability_rows(load(w / "coco" / "stats.json"))
    first = loop["families"].split()[0]
    out += ["", f"Localization of the held-out frames (`eval-loc`, {cam}), masks from the oracle and from "
            f"`{first}`:", ""]
    for mode in ("defaults", "paper"):
        out += [f"**{mode}**{' (`--paper`: the paper search and its pure instance cost)' if mode == 'paper' else ''}",
                "", "| masks | cost | recall (2 m, 2°) | median error | median rotation |"
                " median depth error, signed (estimates ahead of the truth) |", "|---|---|---:|---:|---:|---:|"]
        base = w / hold / cam / "loc"
        out += loc_rows(load(base / f"loop-oracle-{mode}" / "summary.json"), "oracle")
        out += loc_rows(load(base / f"loop-{first}-{mode}" / "summary.json"), first)
        calibrated = load(base / f"loop-{first}-{mode}-calibrated" / "summary.json")
        if calibrated:
            zoom = (calibrated.get("source") or {}).get("zoom", 1.0)
            out += loc_rows(calibrated, f"{first}, calibrated (zoom {zoom} undone)", prior=False)
        weighted = load(base / f"loop-{first}-{mode}-calibrated-area-conf" / "summary.json")
        if weighted:
            out += loc_rows(weighted, f"{first}, calibrated, instances weighted by area × score", prior=False)
        union = load(base / f"loop-{first}-{mode}-calibrated-union-polish" / "summary.json")
        if union:
            out += loc_rows(union, f"{first}, calibrated, the union's outline in the polish "
                            "(`--polish-semantic-weight 1`, the default against coarser maps)", prior=False)
        out.append("")
    out += outline_rows(w, loop, first)
    for fam, name in pictures:
        out += [f"`{fam}` on `{hold}` — RGB | truth | prediction:", "", f"![{fam}]({name})", ""]
    if (bench / "closed_loop_fix_rooftop.png").exists():
        out += ["Data fix: rooftop units no longer punch holes in the roof masks (`render-masks --occluders` "
                "default `trees,cars`; the units belong to the building they stand on). Before | after on the "
                "first training area, changed pixels in yellow:", "", "![rooftop fix](closed_loop_fix_rooftop.png)", ""]
    if (bench / "closed_loop_fix_contrast.jpg").exists():
        out += ["Data fix: touching buildings get contrasting looks (`render-rgb`'s neighbour contrast; "
                "`--no-neighbour-contrast` turns it off), so the boundary the masks draw between row houses shows "
                "in the photo. The same poses rendered without and with it, touching boundaries in yellow; the "
                "header gives the colour contrast across touching and building / background boundaries:", "",
                "![neighbour contrast fix](closed_loop_fix_contrast.jpg)", ""]
    out.append(f"<!-- end:{label} -->")
    return "\n".join(out) + "\n"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--workdir", type=Path, required=True)
    p.add_argument("--report", type=Path, default=Path("bench/closed_loop.md"))
    a = p.parse_args()
    text = section(a.workdir, a.report.parent)
    label = load(a.workdir / "loop.json")["label"]
    old = a.report.read_text() if a.report.exists() else HEADER
    start, end = f"<!-- run:{label} -->", f"<!-- end:{label} -->"
    if start in old and end in old:
        new = old[: old.index(start)] + text.rstrip("\n") + old[old.index(end) + len(end):]
    else:
        new = old.rstrip("\n") + "\n\n" + text
    tmp = a.report.with_name(a.report.name + ".tmp")
    tmp.write_text(new)
    tmp.replace(a.report)
    print(f"loop_report: wrote section {label} of {a.report}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
