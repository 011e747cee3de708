"""bench/loc_sparse.md from the runs of scripts/loc_sparse.sh (see there).

    loc_sparse_report.py WORKDIR "AREAS" "LOD1_AREAS" SPARSE_AREA SPARSE_MAX

Every eval-loc result line is joined with its pose's sampler census (poses.jsonl: visible_buildings,
building_fraction) by frame name. "Old defaults" keep views with at least 3 visible buildings; "new
defaults" also need a building share of at most 0.8 (camera/config.rs, DEFAULT_MAX_BUILDING_FRACTION).
"""
import json
import os
import statistics
import sys

W, AREAS, LOD1, SPARSE, SPARSE_MAX = sys.argv[1], sys.argv[2].split(), sys.argv[3].split(), sys.argv[4], sys.argv[5]
CHOSEN_ON = {"tokyo", "denhaag", f"{SPARSE} sparse"}
MIN_VISIBLE, MAX_FRACTION = 3, 0.8
VARIANTS = [
    ("spill01", "`--polish-spill-weight 0.1` (the union's outline tolerates spill more)"),
    ("wide", "`--basins 8 --survivors 2 --coarse-yaw 12.5/2.5` (more basins, wider yaw fan)"),
]

# What the tables showed when the defaults were chosen (2026-12-05, this script's first run, and 55 views
# of Shibuya's grids at seeds 1–3 with at most 7 buildings each, the sparse set's seed-1 views among them).
FINDINGS = """
## Findings

- **Few buildings are not the problem; a frame filled by buildings is.** Against the exact map, views of
  1–3 buildings on open ground localize like any other (Yokosuka's single buildings included; a
  constructed three-house view in `loc::sparse_tests`). The sparse views that miss are those where a few
  large roofs fill the frame: the outline left is a corner or two and the frame's edge, and the cost is
  flat along the camera's ray through that corner (`loc::sparse_tests`: the cost does not change at all
  over 5 m along it). Of 55 Shibuya views with at most 7 buildings, the 7 with more than 80 % of the ray
  grid on buildings missed 3 times against the exact map (by 9–12 m, with the best cost equal to the
  truth's) and 7 times against the LoD1 map; the 48 others 1 time (a prior 15° off in yaw, outside the
  search volume) and 11 times.
- **Sampler defaults.** `max_building_fraction = 0.8` (new) refuses those views; `min_visible_buildings`
  stays 3: views of one or two buildings localize against the exact map, but against an LoD1 map the
  few-building buckets are the weakest and hold too few views to justify keeping more of them, so the
  default stays on the safe side (a sparse area such as `yokosuka` can set 1 in its `[sampling]` table).
  `min_covered_cells` stays 0: no bucket of covered cells fell short once the filled views were refused.
- **The localizer: nothing kept.** Every sparse failure against the exact map, and all but a few against
  the LoD1 map, has a best cost at or above the cost at the truth: the search found the cost's optimum,
  which is in the wrong place. More basins and a wider yaw fan (`wide`) therefore change little; a more
  spill-tolerant polish (`spill01`) recovered a few LoD1 views (on Shibuya's sparse views at seeds 1–3,
  37 → 41 of 55) but lost one of 40 dense Shibuya LoD1 views and changed nothing on Den Haag's, so it is
  not adopted per query from the instance count on this evidence; it is a change of the cost for every
  query, for the cost's owner to weigh. Raising the union outline's weight in the filter
  (`--semantic-weight 1`) made the LoD1 failures worse. The ground/sky boundary does not exist in cam2
  views (pitch 0° or 45°, 12.5° half field of view: the horizon is never in the frame).
- **LoD1 against sparse views: the blocks' heights per building, not one scale (2026-12-06)**. The 55
  views of Shibuya's grids at seeds 1–3 that the *default* sampler keeps and whose ray census sees at
  most 7 buildings (the cam2-sparse body; oracle masks, instance cost, default search): against LoD1
  blocks at each building's top **74.5 %** (41), at the 70th percentile of its roof heights (3DBAG's
  LoD1.2) **92.7 %** (51), at the median 87.3 % (48). The top's 14 misses are 4–23 m off, 11 of them
  the cost's, 10 of them behind the truth along the axis (the camera moved back to shrink blocks too
  tall). A height scale fitted with the pose was the candidate fix; its stand-in (a throwaway build),
  every vertex of the LoD1 map lowered towards its building's bottom by one factor, loses: × 0.9 61.8 %, × 0.8 58.2 %. What
  is wrong is per building — a podium extruded to its tower's top, a stadium's curved roof as one block
  filling the frame — which one factor cannot absorb, so nothing was built. Nor does treating those
  blocks as outliers help: erasing from the polish's second pass every building with more than half
  of its render outside the query's union at the first pass's optimum gives 76.4 % (42), with more than
  a third 72.7 %, more than 15 % 67.3 % (another throwaway build). LoD1 at the top is the worst case
  of a real LoD1 map.
- **Targets.** Oracle masks on the views the new defaults keep: 100 % on every area, the unseen ones
  (komaba, yokosuka, reported-on) included (target ≥ 99 %). LoD2 queries against the LoD1 map: 89.7 %
  of the views the old defaults keep, 93.2 % of those the new ones keep, pooled over Shibuya, Den Haag
  and the sparse Shibuya views (target ≥ 90 % met overall; **not met on the sparse views alone**, 72 %,
  nor in the 4–15-instance buckets). This is measured only where the defaults were chosen: the shared
  data holds no other LoD2 area with views to sample (Komaba's tiles and Yokosuka are LoD1; the 3DBAG
  sample's ten houses are too small for the sampler's 15 % of building rays).
"""


def load(area, camera, tag):
    """The result lines of one run, each with its pose's census; None when the run is absent."""
    p = os.path.join(W, area, camera, "loc", tag, "results.jsonl")
    if not os.path.exists(p):
        return None
    census = {}
    for line in open(os.path.join(W, area, camera, "poses.jsonl")):
        r = json.loads(line)
        census[r["name"]] = r
    rows = []
    for line in open(p):
        r = json.loads(line)
        c = census[r["name"]]
        r["visible_buildings"] = c.get("visible_buildings", 0)
        r["building_fraction"] = c.get("building_fraction", 0.0)
        r["ok"] = r["translation_error_m"] < 2 and r["rotation_error_deg"] < 2
        rows.append(r)
    return rows


def old_kept(r):
    return r["visible_buildings"] >= MIN_VISIBLE


def new_kept(r):
    return old_kept(r) and r["building_fraction"] <= MAX_FRACTION


def recall(rows):
    return f"{100 * sum(r['ok'] for r in rows) / len(rows):.1f} ({len(rows)})" if rows else "–"


def runs():
    """(set name, map, rows) for every run present."""
    out = []
    for a in AREAS:
        for tag, label in (("exact", "own"), ("lod1", "LoD1")):
            rows = load(a, "cam2", tag)
            if rows:
                out.append((a, label, rows))
    for tag, label in (("exact", "own"), ("lod1", "LoD1")):
        rows = load(SPARSE, "cam2-sparse", tag)
        if rows:
            out.append((f"{SPARSE} sparse", label, rows))
    return out


def bucket_table(title, all_runs, key, buckets, note):
    print(f"\n## {title}\n\n{note}\n")
    print("| map | areas | " + " | ".join(b[0] for b in buckets) + " |")
    print("|---|---|" + "---:|" * len(buckets))
    for label in ("own", "LoD1"):
        for group, members in (("chosen on", True), ("reported on", False)):
            rows = [r for s, m, rs in all_runs if m == label and (s in CHOSEN_ON) == members for r in rs]
            if rows:
                cells = [recall([r for r in rows if lo <= key(r) < hi]) for _, lo, hi in buckets]
                print(f"| {label} | {group} | " + " | ".join(cells) + " |")


def main():
    all_runs = runs()
    print("# Views with few buildings (issue 40)\n")
    print(
        "Generated by `scripts/loc_sparse.sh` (release build; oracle masks, default priors and search, "
        "cam2 grid views; recall at (2 m, 2°) in %, queries in brackets). Each area is sampled with a census "
        "sampler that keeps every view the other checks allow (at least 1 visible building, any building "
        "share), so that views the defaults refuse are measured too. *Own*: the area's own map; *LoD1*: "
        "its LoD1 coarsening (`--map-lod1`, every vertex more than 1 m above a building's bottom moved to "
        "its top). "
        f"*{SPARSE} sparse*: the first views of {SPARSE}'s whole grid whose ray census sees at most "
        f"{SPARSE_MAX} buildings. *Old defaults*: `min_visible_buildings = {MIN_VISIBLE}`; *new defaults*: "
        f"also `max_building_fraction = {MAX_FRACTION}` (at most {MAX_FRACTION:.0%} of the sampler's ray grid "
        "on buildings). The thresholds were chosen on tokyo, denhaag and the sparse Shibuya set and are "
        "reported on the other areas, which played no part in the choice."
    )
    print("\n## What the defaults keep, per area\n")
    print("| views | map | all (census) | old defaults | new defaults | refused by the building share: recall |")
    print("|---|---|---:|---:|---:|---:|")
    for s, label, rows in all_runs:
        refused = [r for r in rows if old_kept(r) and not new_kept(r)]
        tag = "" if s in CHOSEN_ON else " (reported on)"
        print(
            f"| {s}{tag} | {label} | {recall(rows)} | {recall([r for r in rows if old_kept(r)])} | "
            f"{recall([r for r in rows if new_kept(r)])} | {recall(refused)} |"
        )
    for label in ("own", "LoD1"):
        for group, members in (("chosen-on", True), ("reported-on", False)):
            rows = [r for s, m, rs in all_runs if m == label and (s in CHOSEN_ON) == members for r in rs]
            if rows:
                refused = [r for r in rows if old_kept(r) and not new_kept(r)]
                print(f"| **all {group} views** | {label} | {recall(rows)} | {recall([r for r in rows if old_kept(r)])} | "
                      f"{recall([r for r in rows if new_kept(r)])} | {recall(refused)} |")
    inf = float("inf")
    bucket_table(
        "Recall per visible buildings (the sampler's ray census)",
        all_runs,
        lambda r: r["visible_buildings"],
        [("1", 1, 2), ("2", 2, 3), ("3", 3, 4), ("4–7", 4, 8), ("8–15", 8, 16), ("16+", 16, inf)],
        "All views of the census sampler, pooled over the areas of each group.",
    )
    bucket_table(
        "Recall per building share (the sampler's ray census)",
        all_runs,
        lambda r: r["building_fraction"],
        [("< 0.5", 0, 0.5), ("0.5–0.7", 0.5, 0.7), ("0.7–0.8", 0.7, 0.8001), ("0.8–0.9", 0.8001, 0.9),
         ("≥ 0.9", 0.9, inf)],
        "All views with at least 3 visible buildings, pooled; the new default keeps the first three columns.",
    )
    print("\n## Recall per query instances, before / after (old / new sampler defaults)\n")
    print("Query instances: the oracle mask's instances at the render width (eval-loc's buckets). Before: "
          "the views the old defaults keep; after: those the new defaults keep (the same queries, fewer).\n")
    buckets = [("1", 1, 2), ("2–3", 2, 4), ("4–7", 4, 8), ("8–15", 8, 16), ("16+", 16, inf)]
    print("| map | areas | defaults | " + " | ".join(b[0] for b in buckets) + " | ≤ 8 / ≥ 9 cells | all |")
    print("|---|---|---|" + "---:|" * (len(buckets) + 2))
    for label in ("own", "LoD1"):
        for group, members in (("chosen on", True), ("reported on", False)):
            pooled = [r for s, m, rs in all_runs if m == label and (s in CHOSEN_ON) == members for r in rs]
            for name, kept in (("old", old_kept), ("new", new_kept)):
                rows = [r for r in pooled if kept(r)]
                if not rows:
                    continue
                cells = [recall([r for r in rows if lo <= r["query_instances"] < hi]) for _, lo, hi in buckets]
                few = [r for r in rows if r["covered_frame_cells"] <= 8]
                many = [r for r in rows if r["covered_frame_cells"] > 8]
                print(f"| {label} | {group} | {name} | " + " | ".join(cells)
                      + f" | {recall(few)} / {recall(many)} | {recall(rows)} |")
    print("\n## What the localizer can do with few buildings: variants on the sparse set\n")
    print(f"The {SPARSE} sparse views (all of them, census sampler), default search against the variants. "
          "Kept only if better; none is the default (see the text below the table).\n")
    print("| variant | map | recall | failures with best cost ≥ cost at the truth | median s/query |")
    print("|---|---|---:|---:|---:|")
    for tag, label in [("exact", "default"), ("lod1", "default")] + [(f"{m}-{t}", v) for t, v in VARIANTS
                                                                     for m in ("exact", "lod1")]:
        rows = load(SPARSE, "cam2-sparse", tag)
        if not rows:
            continue
        amb = sum(1 for r in rows if not r["ok"] and r["best_cost"] >= r["cost_at_gt"] - 1e-4)
        secs = statistics.median(r["seconds"] for r in rows)
        m = "LoD1" if tag.startswith("lod1") else "own"
        print(f"| {label} | {m} | {recall(rows)} | {amb} of {sum(not r['ok'] for r in rows)} | {secs:.2f} |")
    print(FINDINGS)
    speed = os.path.join(W, "speed.tsv")
    if os.path.exists(speed):
        print("\n## Speed: Shibuya cam2\n")
        print("`insgen --workdir W eval-loc --area tokyo --camera cam2 --oracle --overlays 0 --limit 20` on the "
              "default sampler's views, one run after the other; median search seconds per query "
              "(summary.json), the run's wall and user CPU seconds, and the 1-minute load average before it "
              "(the machine's 2 cores were shared with other jobs).\n")
        print("| run | load average | median s/query | wall s | user CPU s | user CPU s / query / 2 cores |")
        print("|---:|---:|---:|---:|---:|---:|")
        medians = []
        for line in open(speed):
            i, load_avg, times = line.rstrip("\n").split("\t")
            wall, user = times.split()
            summ = json.load(open(os.path.join(W, "speed", "tokyo", "cam2", "loc", f"speed{i}", "summary.json")))
            medians.append(summ["median_seconds_per_query"])
            n = summ["queries"]
            print(f"| {i} | {load_avg} | {medians[-1]:.2f} | {wall} | {user} | {float(user) / n / 2:.2f} |")
        if medians:
            print(f"\nMedian of the runs: **{statistics.median(medians):.2f} s/query** of wall clock on the loaded "
                  "machine. The user CPU seconds of a whole run (scene load, query setup, search, cost at the "
                  "truth) over its queries and the 2 cores bound what an idle 2-core machine would take if the "
                  "search scaled perfectly over both; the wall-clock target (≤ 1 s) was not measured on an idle "
                  "machine, none was available. This branch does not change the search: only the sampler "
                  "chooses other views.")


main()
