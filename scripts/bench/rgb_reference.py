"""Converged reference crops for the RGB quality bench (scripts/bench_rgb.sh).

Run with the bpy interpreter:
    .venv-blender/bin/python scripts/bench/rgb_reference.py JOB.json OUT_DIR MODE SAMPLES CROP_W CROP_H [FRAMES]

JOB.json is a job insgen wrote (render-rgb keeps it under <camera>/blender/). The scene is built exactly as
scripts/blender/render_rgb.py builds it (same functions), then the first FRAMES frames (default all) are
rendered with SAMPLES samples per pixel and without denoiser (MODE "reference": the converged image of the
job's look; a path-traced look gets the richest light transport insgen ever used, 4 bounces, 2 diffuse,
2 glossy, while the direct-lighting look has nothing to bounce and keeps the job's) or with the settings
render-rgb used before issue 14 (MODE "old", path-traced jobs only: 4 bounces, OpenImageDenoise at HIGH
quality with the ACCURATE prefilter), restricted to the centred CROP_W x CROP_H pixel window of the frame
(Cycles' render border: each pixel's samples do not depend on the border, so the crop equals the same
window of a full render). MODE "job" renders the whole frame with the job's own settings (SAMPLES, CROP_W
and CROP_H are ignored): Blender's frame as render-rgb gets it, before insgen applies the camera effects
(white balance, vignetting, blur, noise), which are deliberate and not a rendering error. Every mode sets
each frame's drawn look (sun, sky, haze, exposure) as render-rgb does. Writes OUT_DIR/<frame>.png (8-bit
sRGB) and prints one line per frame: "REF <frame> <wall seconds> <cpu seconds>".
"""

import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "blender"))
import render_rgb as R  # noqa: E402


def main(argv):
    job_path, out_dir, mode = argv[1], argv[2], argv[3]
    samples, crop_w, crop_h = int(argv[4]), int(argv[5]), int(argv[6])
    limit = int(argv[7]) if len(argv) > 7 else None
    if mode not in ("reference", "old", "job"):
        raise SystemExit(f"MODE must be reference, old or job, not {mode!r}")
    import bpy

    job = R.load_job(job_path)
    if mode == "old" and job["lighting"] != "path":
        raise SystemExit(f"{job_path}: MODE old needs a path-traced job (render-rgb --lighting path)")
    scene = R.reset_scene(bpy)
    R.configure_render(bpy, scene, job)
    placed = R.import_models(bpy, job)
    R.build_look(bpy, scene, job, placed)
    cam = R.make_camera(bpy, scene)
    c = scene.cycles
    os.makedirs(out_dir, exist_ok=True)
    if mode == "job":
        for frame in job["frames"][:limit]:
            render_frame(bpy, scene, cam, placed, job, frame, out_dir)
        return
    c.samples = samples
    c.use_adaptive_sampling = False
    c.use_denoising = mode == "old"
    if mode == "old":
        c.denoiser = "OPENIMAGEDENOISE"
        c.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        c.denoising_prefilter = "ACCURATE"
        c.denoising_quality = "HIGH"
    if job["lighting"] == "path":
        c.max_bounces = 4
        c.diffuse_bounces = 2
        c.glossy_bounces = 2
        c.transmission_bounces = 2
        c.transparent_max_bounces = 4
    r = scene.render
    for frame in job["frames"][:limit]:
        w, h = r.resolution_x, r.resolution_y
        x0, y0 = (w - crop_w) // 2, (h - crop_h) // 2
        r.use_border = True
        r.use_crop_to_border = True
        # Border fractions are measured from the bottom-left corner.
        r.border_min_x, r.border_max_x = x0 / w, (x0 + crop_w) / w
        r.border_min_y, r.border_max_y = (h - y0 - crop_h) / h, (h - y0) / h
        render_frame(bpy, scene, cam, placed, job, frame, out_dir)


def render_frame(bpy, scene, cam, placed, job, frame, out_dir):
    """Renders one frame as render_rgb.main does (camera, visibility, the frame's look) into OUT_DIR."""
    R.prepare_frame(scene, cam, placed, job, frame, None)
    t0, c0 = time.time(), time.process_time()
    bpy.ops.render.render(write_still=False)
    out = dict(frame)
    out["png"] = os.path.join(out_dir, frame["name"] + ".png")
    out["exr"] = None
    R.save(bpy, scene, out, "rgb")
    print(f"REF {frame['name']} {time.time() - t0:.2f} {time.process_time() - c0:.2f}", flush=True)


if __name__ == "__main__":
    main(sys.argv)
