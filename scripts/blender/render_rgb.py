"""insgen render-rgb: the Blender side of RGB and ID rendering, driven by one JSON job file.

Run as
    <venv>/bin/python render_rgb.py JOB.json            (bpy installed as a Python module), or
    blender -b --factory-startup -P render_rgb.py -- JOB.json

The job file is written by insgen (src/blender/job.rs; schema: schemas/blender_job.schema.json). Nothing in
this script is generated: every value comes from the job. The script

1. resets Blender to an empty factory scene and applies the render settings (engine, samples, seed,
   Standard view transform, PNG 8-bit / EXR float32 outputs);
2. imports every model (glTF/GLB) of the job and places it in the area's ENU frame: the glTF importer
   converts y-up to Blender's z-up, Blender (x, y, z) = glTF (x, -z, y); the job gives ENU_from_glTF per
   model, so each imported model is parented to an empty whose matrix is ENU_from_glTF @ inverse(Y2Z);
3. builds the look: in "rgb" mode procedural facade/roof materials varied per building (LoD models) —
   except faces that carry a source appearance (scene.glb's _APPEARANCE attribute and
   asset.extras.appearance_materials: textures from textures/ next to the GLB, X3D/CityJSON colours),
   which show it, lit the same way —, the models' own materials shown as emission (photogrammetry), a textured ground plane, a sky texture and a
   sun, lit as the job's `lighting` says ("direct": Lambertian surfaces, a point-like sun, the sky as a
   non-sampled ambient and glass-reflection emission, no bounces, so nothing but anti-aliasing is noisy;
   "path": Principled BSDFs, the sky as an environment light, bounces); in "ids" mode one flat emission
   material whose red channel is the building ID (exact in float32);
4. renders every frame with the camera given in Blender terms (lens, sensor, shift, pixel aspect, world
   matrix), writes the images to the temporary paths given in the job, and prints one protocol line per
   frame on stdout.

Protocol: lines on stdout starting with "INSGEN " followed by a JSON object:
    {"ready": {"models": n, "seconds": t, "device": d, "blender": v, "bounds": [...]}}
                                                               after the scene is built (d: the Cycles
                                                               device, CPU/OPTIX/CUDA/HIP/ONEAPI/METAL)
    {"done": "<frame>", "seconds": t, "cpu_seconds": c}         after a frame's files are written
                                                               (wall-clock and CPU time of all threads)
    {"error": "<message>", "frame": "<frame or null>"}          before exiting with status 1
Everything else on stdout/stderr is Blender's own logging.
"""

import json
import math
import os
import sys
import time
import traceback

PROTOCOL_PREFIX = "INSGEN "
JOB_FORMAT = "insgen-blender-job"
JOB_VERSION = 4
# Name of the per-face building-ID attribute the script derives from _FEATURE_ID_0 (face domain, so no
# interpolation can perturb the value: every pixel of a face reads the exact float).
FACE_ID_ATTRIBUTE = "insgen_building_id"
# Face-domain contrast class of the building (job look "contrast", src/scene/adjacency.rs); -1 = none.
CONTRAST_ATTRIBUTE = "insgen_contrast_class"
FEATURE_ID_ATTRIBUTE = "_FEATURE_ID_0"
# Per-vertex appearance number of a scene.glb with textured LoD models (0 = none: the procedural look;
# k = asset.extras.appearance_materials[k - 1]); see src/scene/glb.rs.
APPEARANCE_ATTRIBUTE = "_APPEARANCE"


def emit(obj):
    sys.stdout.write(PROTOCOL_PREFIX + json.dumps(obj) + "\n")
    sys.stdout.flush()


def job_path_from_argv(argv):
    """The job path: the argument after '--' (blender -P), else the first argument (python)."""
    if "--" in argv:
        rest = argv[argv.index("--") + 1:]
    else:
        rest = argv[1:]
    if len(rest) != 1:
        raise SystemExit("usage: render_rgb.py JOB.json  (or blender -b -P render_rgb.py -- JOB.json)")
    return rest[0]


def load_job(path):
    with open(path, "r", encoding="utf-8") as f:
        job = json.load(f)
    if job.get("format") != JOB_FORMAT:
        raise ValueError(f"{path}: not an insgen Blender job (format = {job.get('format')!r})")
    if job.get("version") != JOB_VERSION:
        raise ValueError(f"{path}: job version {job.get('version')!r}, this script reads {JOB_VERSION}")
    return job


# --------------------------------------------------------------------------------------------- scene


def reset_scene(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    for block in (bpy.data.meshes, bpy.data.materials, bpy.data.lights, bpy.data.cameras, bpy.data.images):
        for item in list(block):
            block.remove(item)
    return scene


def configure_render(bpy, scene, job):
    r = scene.render
    r.resolution_percentage = 100
    r.use_border = False
    r.film_transparent = False
    r.use_persistent_data = True
    # No metadata in the files (dates, render times, host names): same job, same bytes.
    for prop in r.bl_rna.properties:
        if prop.identifier.startswith("use_stamp"):
            setattr(r, prop.identifier, False)
    threads = int(job.get("threads", 0))
    if threads > 0:
        r.threads_mode = "FIXED"
        r.threads = threads
    else:
        r.threads_mode = "AUTO"
    vs = scene.view_settings
    vs.view_transform = "Standard"
    vs.look = "None"
    vs.exposure = float(job["look"].get("exposure", 0.0)) if job["mode"] == "rgb" else 0.0
    vs.gamma = 1.0
    scene.display_settings.display_device = "sRGB"
    scene.sequencer_colorspace_settings.name = "sRGB"

    engine = job["engine"]
    if job["mode"] == "ids" or engine == "cycles":
        r.engine = "CYCLES"
        c = scene.cycles
        device = select_device(bpy, scene, job.get("device", "cpu"))
        c.seed = int(job["seed"])
        c.use_animated_seed = False
        c.use_adaptive_sampling = False
        c.use_denoising = False
        if job["mode"] == "ids":
            # One sample per pixel taken (up to 0.005 px) at the pixel centre: a box filter of the
            # smallest allowed width, so the sample position matches a rasteriser's pixel-centre rule.
            c.samples = 1
            c.pixel_filter_type = "BOX"
            c.filter_width = 0.01
            c.max_bounces = 0
            c.sample_clamp_direct = 0.0
            c.sample_clamp_indirect = 0.0
        else:
            c.samples = int(job["samples"])
            c.pixel_filter_type = "BLACKMAN_HARRIS"
            c.filter_width = 1.5
            # Bounce limits were chosen by measurement (bench/rgb_quality.md): past the first diffuse
            # bounce the procedural look changes by less than the 8-bit quantisation, and every bounce
            # costs a ray per sample. Unlit (photogrammetry) content needs none.
            bounces = int(job.get("max_bounces", 4))
            c.max_bounces = bounces
            c.diffuse_bounces = min(bounces, 2)
            c.glossy_bounces = min(bounces, 2)
            c.transmission_bounces = min(bounces, 2)
            c.transparent_max_bounces = 4
            c.sample_clamp_indirect = 10.0
            if job.get("lighting") == "direct":
                # One sun and no sampled emitters: a light tree has nothing to choose between.
                c.use_light_tree = False
            if job.get("denoise"):
                # OpenImageDenoise guided by albedo and normal passes; its quality and the prefilter of
                # the guides set the cost (HIGH + ACCURATE, Blender's defaults, cost ~4x FAST + FAST on
                # a 1920x1080 frame).
                quality = str(job.get("denoise_quality", "high")).upper()
                c.use_denoising = True
                c.denoiser = "OPENIMAGEDENOISE"
                c.denoising_input_passes = "RGB_ALBEDO_NORMAL"
                c.denoising_prefilter = "ACCURATE" if quality == "HIGH" else "FAST"
                if hasattr(c, "denoising_quality"):
                    c.denoising_quality = quality
                if hasattr(c, "denoising_use_gpu"):
                    c.denoising_use_gpu = device != "CPU"
        return device
    elif engine == "workbench":
        r.engine = "BLENDER_WORKBENCH"
        sh = scene.display.shading
        sh.light = "STUDIO"
        # The scene's flat per-building colour attribute (COLOR_0), when there is one.
        sh.color_type = "VERTEX"
        sh.show_shadows = True
        sh.show_cavity = False
        scene.display.render_aa = "8"
        return None
    else:
        raise ValueError(f"unknown engine {engine!r} (expected cycles or workbench)")


# Cycles device backends from best to worst, as `auto` tries them.
GPU_BACKENDS = ("OPTIX", "CUDA", "HIP", "ONEAPI", "METAL")


def select_device(bpy, scene, wanted):
    """Sets the Cycles device and returns its name ("CPU", "OPTIX", ...).

    "cpu" is the CPU; "auto" the first backend of GPU_BACKENDS for which Blender reports a device (all of
    that backend's devices are enabled), else the CPU; a named backend must have a device, otherwise the
    job fails with the devices Blender does report.
    """
    wanted = str(wanted).upper()
    scene.cycles.device = "CPU"
    if wanted == "CPU":
        return "CPU"
    try:
        prefs = bpy.context.preferences.addons["cycles"].preferences
    except (KeyError, AttributeError):
        prefs = None
    found = {}
    candidates = GPU_BACKENDS if wanted == "AUTO" else (wanted,)
    for backend in candidates:
        if prefs is None:
            break
        try:
            prefs.compute_device_type = backend
        except TypeError:  # a backend this build of Blender does not know
            continue
        prefs.get_devices()
        devices = [d for d in prefs.devices if d.type == backend]
        found[backend] = [d.name for d in devices]
        if devices:
            for d in prefs.devices:
                d.use = d.type == backend
            scene.cycles.device = "GPU"
            return backend
    if prefs is not None:
        try:
            prefs.compute_device_type = "NONE"
        except TypeError:
            pass
    if wanted == "AUTO":
        return "CPU"
    raise RuntimeError(f"device {wanted.lower()} requested but Blender reports no {wanted} device "
                       f"(found: {found or 'no Cycles preferences'}); use --device auto or cpu")


def y2z_inverse(Matrix):
    # glTF y-up to Blender z-up as the importer applies it: (x, y, z) -> (x, -z, y). Its inverse maps
    # Blender back to glTF: (x, y, z) -> (x, z, -y).
    return Matrix(((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), (0.0, -1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)))


def import_models(bpy, job):
    """Imports each model and returns a list of (root empty, [mesh objects])."""
    from mathutils import Matrix

    placed = []
    contrast = (job.get("look") or {}).get("contrast") if job["mode"] == "rgb" else None
    classes = {int(b): float(c) for b, c in contrast["building_classes"]} if contrast else None
    for index, model in enumerate(job["models"]):
        before = set(bpy.data.objects)
        result = bpy.ops.import_scene.gltf(filepath=model["glb"], merge_vertices=False)
        if "FINISHED" not in result:
            raise RuntimeError(f"glTF import of {model['glb']} failed: {result}")
        new_objects = [o for o in bpy.data.objects if o not in before]
        root = bpy.data.objects.new(f"insgen_model_{index}", None)
        bpy.context.scene.collection.objects.link(root)
        root.matrix_world = Matrix(model["enu_from_gltf"]) @ y2z_inverse(Matrix)
        for obj in new_objects:
            if obj.parent is None:
                basis = obj.matrix_basis.copy()
                obj.parent = root
                obj.matrix_parent_inverse = Matrix.Identity(4)
                obj.matrix_basis = basis
        meshes = [o for o in new_objects if o.type == "MESH"]
        for obj in meshes:
            add_face_ids(obj, classes if model["kind"] == "lod" else None)
        placed.append((root, meshes, model))
    bpy.context.view_layer.update()
    return placed


def add_face_ids(obj, classes=None):
    """Copies the per-vertex _FEATURE_ID_0 to a face-domain attribute (value of the face's first corner),
    and with `classes` ({building ID: contrast class}) writes each face's class to CONTRAST_ATTRIBUTE."""
    mesh = obj.data
    src = mesh.attributes.get(FEATURE_ID_ATTRIBUTE)
    n_faces = len(mesh.polygons)
    face_ids = [0.0] * n_faces
    if src is not None and n_faces:
        values = [0.0] * len(src.data)
        src.data.foreach_get("value", values)
        if src.domain == "POINT":
            starts = [0] * n_faces
            mesh.polygons.foreach_get("loop_start", starts)
            corner_verts = [0] * len(mesh.loops)
            mesh.loops.foreach_get("vertex_index", corner_verts)
            face_ids = [float(round(values[corner_verts[s]])) for s in starts]
        elif src.domain == "FACE":
            face_ids = [float(round(v)) for v in values]
        elif src.domain == "CORNER":
            starts = [0] * n_faces
            mesh.polygons.foreach_get("loop_start", starts)
            face_ids = [float(round(values[s])) for s in starts]
    attr = mesh.attributes.new(FACE_ID_ATTRIBUTE, "FLOAT", "FACE")
    if n_faces:
        attr.data.foreach_set("value", face_ids)
    if classes is not None:
        cls = mesh.attributes.new(CONTRAST_ATTRIBUTE, "FLOAT", "FACE")
        if n_faces:
            cls.data.foreach_set("value", [classes.get(int(f), -1.0) for f in face_ids])


def model_bounds(placed):
    bounds = []
    for _root, meshes, _model in placed:
        lo = [math.inf] * 3
        hi = [-math.inf] * 3
        for obj in meshes:
            mw = obj.matrix_world
            for v in obj.data.vertices:
                p = mw @ v.co
                for k in range(3):
                    lo[k] = min(lo[k], p[k])
                    hi[k] = max(hi[k], p[k])
        bounds.append(None if lo[0] == math.inf else [lo, hi])
    return bounds


# --------------------------------------------------------------------------------------------- looks


# Nodes whose values change per frame (apply_frame_look): filled while the look is built.
LIVE = {"ambient": [], "reflection": [], "haze_beta": [], "haze_color": [], "sun": None, "sky": None,
        "world_mix": None, "world_haze": None, "world_bg": None}

# Sky ambient colour per unit of sky strength, by weather: a blue sky lights shadows blue; haze and cloud
# scatter whiter light.
AMBIENT_BY_SKY = {"clear": (0.5, 0.62, 0.8), "hazy": (0.56, 0.62, 0.72), "overcast": (0.62, 0.64, 0.67)}
# How much the sky seen by the camera turns to the haze colour, and sky turbidity, by weather.
SKY_HAZE_MIX = {"clear": 0.12, "hazy": 0.55, "overcast": 0.92}
SKY_TURBIDITY = {"clear": 2.5, "hazy": 6.0, "overcast": 10.0}


def new_material(bpy, name):
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    return mat, nt


def node(nt, kind, **props):
    n = nt.nodes.new(kind)
    for k, v in props.items():
        setattr(n, k, v)
    return n


def math_node(nt, op, a, b=None, clamp=False):
    n = node(nt, "ShaderNodeMath", operation=op, use_clamp=clamp)
    link_or_set(nt, n.inputs[0], a)
    if b is not None:
        link_or_set(nt, n.inputs[1], b)
    return n.outputs[0]


def link_or_set(nt, socket, value):
    if hasattr(value, "is_output"):
        nt.links.new(value, socket)
    else:
        socket.default_value = value


def socket(sockets, identifier):
    """A node socket by its identifier (names repeat across the Mix node's typed variants)."""
    for s in sockets:
        if s.identifier == identifier:
            return s
    raise KeyError(identifier)


def mix_color(nt, factor, a, b):
    n = node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="MIX", clamp_factor=True)
    link_or_set(nt, socket(n.inputs, "Factor_Float"), factor)
    link_or_set(nt, socket(n.inputs, "A_Color"), a)
    link_or_set(nt, socket(n.inputs, "B_Color"), b)
    return socket(n.outputs, "Result_Color")


def mix_float(nt, factor, a, b):
    n = node(nt, "ShaderNodeMix", data_type="FLOAT", clamp_factor=True)
    link_or_set(nt, socket(n.inputs, "Factor_Float"), factor)
    link_or_set(nt, socket(n.inputs, "A_Float"), a)
    link_or_set(nt, socket(n.inputs, "B_Float"), b)
    return socket(n.outputs, "Result_Float")


def per_building_random(nt, building_id, look_seed, channel):
    """A uniform [0, 1) value per (building, seed, channel): white noise of (id, seed, channel)."""
    combine = node(nt, "ShaderNodeCombineXYZ")
    nt.links.new(building_id, combine.inputs["X"])
    combine.inputs["Y"].default_value = float(look_seed % 100003)
    combine.inputs["Z"].default_value = float(channel)
    wn = node(nt, "ShaderNodeTexWhiteNoise", noise_dimensions="3D")
    nt.links.new(combine.outputs["Vector"], wn.inputs["Vector"])
    return wn.outputs["Value"]


def by_lightness(colors):
    """The palette sorted by luminance (Rec. 709 weights of the linear RGB), darkest first."""
    return sorted(colors, key=lambda c: 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2])


def contrast_class(nt):
    attr = node(nt, "ShaderNodeAttribute", attribute_type="GEOMETRY", attribute_name=CONTRAST_ATTRIBUTE)
    # Faces without a class (-1) take class 0.
    return math_node(nt, "MAXIMUM", attr.outputs["Fac"], 0.0)


def contrast_pick(nt, look, r):
    """The palette position of band `class` of K, at `r` ∈ [0, 1) within it: (class + r) / K."""
    k = float(look["contrast"]["classes"])
    return math_node(nt, "DIVIDE", math_node(nt, "ADD", contrast_class(nt), math_node(nt, "MULTIPLY", r, 0.999)), k)


def contrast_factor(nt, look, lo, hi):
    """lo + (hi − lo) · class / (K − 1): a brightness factor that grows with the class."""
    k = max(float(look["contrast"]["classes"]) - 1.0, 1.0)
    return math_node(nt, "ADD", math_node(nt, "MULTIPLY", contrast_class(nt), (hi - lo) / k), lo)


def scale_color(nt, color, factor):
    mix = node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="MULTIPLY", clamp_factor=True)
    socket(mix.inputs, "Factor_Float").default_value = 1.0
    link_or_set(nt, socket(mix.inputs, "A_Color"), color)
    rgb = node(nt, "ShaderNodeCombineXYZ")
    for k in ("X", "Y", "Z"):
        nt.links.new(factor, rgb.inputs[k])
    nt.links.new(rgb.outputs["Vector"], socket(mix.inputs, "B_Color"))
    return socket(mix.outputs, "Result_Color")


def palette(nt, fac, colors):
    ramp = node(nt, "ShaderNodeValToRGB")
    ramp.color_ramp.interpolation = "CONSTANT"
    els = ramp.color_ramp.elements
    while len(els) > 1:
        els.remove(els[-1])
    n = len(colors)
    els[0].position = 0.0
    els[0].color = (*colors[0], 1.0)
    for i in range(1, n):
        e = els.new(i / n)
        e.color = (*colors[i], 1.0)
    nt.links.new(fac, ramp.inputs["Fac"])
    return ramp.outputs["Color"]


# Linear-RGB facade, roof and glass palettes (sRGB-ish values converted by eye to linear).
FACADE_COLORS = [
    (0.55, 0.50, 0.42), (0.62, 0.62, 0.60), (0.35, 0.14, 0.09), (0.75, 0.72, 0.66), (0.25, 0.25, 0.26),
    (0.48, 0.40, 0.30), (0.70, 0.66, 0.55), (0.42, 0.44, 0.47), (0.30, 0.20, 0.14), (0.82, 0.80, 0.78),
]
# The varied look's wider palette adds concrete, metal cladding and painted render.
FACADE_COLORS_WIDE = FACADE_COLORS + [
    (0.38, 0.37, 0.35), (0.52, 0.52, 0.50), (0.30, 0.34, 0.38), (0.60, 0.45, 0.32), (0.45, 0.52, 0.48),
]
ROOF_COLORS = [
    (0.10, 0.10, 0.11), (0.22, 0.22, 0.21), (0.05, 0.05, 0.055), (0.30, 0.29, 0.27), (0.06, 0.09, 0.04),
    (0.20, 0.07, 0.04), (0.16, 0.17, 0.18), (0.36, 0.35, 0.33), (0.13, 0.12, 0.10),
]
GLASS_COLORS = [(0.05, 0.08, 0.12), (0.08, 0.10, 0.10), (0.10, 0.14, 0.20), (0.04, 0.05, 0.06)]


def building_material(bpy, look, lighting):
    """One shared material; per-building variety comes from the face attribute holding the building ID.

    Facades: a palette colour, a brick or plaster texture, and a window grid laid out in facade
    coordinates (horizontal distance along the wall, height above ground) with per-building floor height,
    window spacing and window-to-wall ratio; curtain-wall buildings are mostly glass. Roofs (faces whose
    normal points up) get a roof palette with noise and rooftop clutter.

    Walls and roofs are two shaders joined by a Mix Shader whose factor is exactly 0 or 1: Cycles' SVM
    skips the nodes that feed only the branch with weight 0, so a pixel pays for the textures of its own
    surface kind only. Texture detail stops near the pixel footprint of a UAV view (~0.1 m at 500 m for
    the cam2 lens): finer octaves are aliasing that costs time and that the denoiser must remove again.
    """
    seed = int(look["seed"])
    mat, nt = new_material(bpy, "insgen_building")
    out = node(nt, "ShaderNodeOutputMaterial")

    attr = node(nt, "ShaderNodeAttribute", attribute_type="GEOMETRY", attribute_name=FACE_ID_ATTRIBUTE)
    bid = attr.outputs["Fac"]
    geo = node(nt, "ShaderNodeNewGeometry")
    pos = node(nt, "ShaderNodeSeparateXYZ")
    nt.links.new(geo.outputs["Position"], pos.inputs["Vector"])
    nrm = node(nt, "ShaderNodeSeparateXYZ")
    nt.links.new(geo.outputs["True Normal"], nrm.inputs["Vector"])
    nz = nrm.outputs["Z"]
    roof = math_node(nt, "GREATER_THAN", nz, 0.7)

    wall = facade_shader(nt, look, lighting, bid, seed, geo, pos, nrm)
    top = roof_shader(nt, look, lighting, bid, seed, geo, pos)
    mix = node(nt, "ShaderNodeMixShader")
    nt.links.new(roof, mix.inputs["Fac"])
    nt.links.new(wall, mix.inputs[1])
    nt.links.new(top, mix.inputs[2])
    nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    if lighting == "direct":
        # The emission stands for sky light already integrated: never a light source to sample.
        mat.cycles.emission_sampling = "NONE"
    return mat


def facade_shader(nt, look, lighting, bid, seed, geo, pos, nrm):
    """Walls (and every face that is not a roof): palette, brick or plaster, and the window grid."""
    ground_m = float(look["ground_enu_m"])
    r_color = per_building_random(nt, bid, seed, 1)
    r_style = per_building_random(nt, bid, seed, 2)
    r_floor = per_building_random(nt, bid, seed, 3)
    r_space = per_building_random(nt, bid, seed, 4)
    r_ratio = per_building_random(nt, bid, seed, 5)
    r_glass = per_building_random(nt, bid, seed, 7)
    r_bright = per_building_random(nt, bid, seed, 8)

    # Horizontal facade coordinate: position projected on the wall's horizontal tangent (-ny, nx).
    t = math_node(nt, "ADD", math_node(nt, "MULTIPLY", pos.outputs["X"], math_node(nt, "MULTIPLY", nrm.outputs["Y"], -1.0)),
                  math_node(nt, "MULTIPLY", pos.outputs["Y"], nrm.outputs["X"]))
    height = math_node(nt, "SUBTRACT", pos.outputs["Z"], ground_m)

    floor_h = math_node(nt, "ADD", math_node(nt, "MULTIPLY", r_floor, 1.4), 2.9)
    spacing = math_node(nt, "ADD", math_node(nt, "MULTIPLY", r_space, 2.5), 2.2)
    ratio = math_node(nt, "ADD", math_node(nt, "MULTIPLY", r_ratio, 0.45), 0.3)
    curtain = math_node(nt, "GREATER_THAN", r_style, 0.78)
    ratio = mix_float(nt, curtain, ratio, 0.9)

    u = math_node(nt, "FRACT", math_node(nt, "DIVIDE", t, spacing))
    v = math_node(nt, "FRACT", math_node(nt, "DIVIDE", height, floor_h))
    half = math_node(nt, "MULTIPLY", ratio, 0.5)
    du = math_node(nt, "ABSOLUTE", math_node(nt, "SUBTRACT", u, 0.5))
    dv = math_node(nt, "ABSOLUTE", math_node(nt, "SUBTRACT", v, 0.55))
    in_u = math_node(nt, "LESS_THAN", du, half)
    in_v = math_node(nt, "LESS_THAN", dv, math_node(nt, "MULTIPLY", half, 0.8))
    # No windows on the ground floor's lowest metre, nor on sloped or downward faces.
    above = math_node(nt, "GREATER_THAN", height, 1.0)
    upright = math_node(nt, "LESS_THAN", math_node(nt, "ABSOLUTE", nrm.outputs["Z"]), 0.3)
    window = math_node(nt, "MULTIPLY", math_node(nt, "MULTIPLY", in_u, in_v), math_node(nt, "MULTIPLY", above, upright))

    # Wall colour: palette pick, brightness jitter, brick texture for the "brick" style, plaster noise.
    # With contrast classes the pick comes from the class's lightness band and the jitter is narrower.
    facades = FACADE_COLORS_WIDE if look.get("wide_palette") else FACADE_COLORS
    if look.get("contrast"):
        # The band, and a brightness that steps with the class (0.7 … 1.3) with a little jitter.
        base = palette(nt, contrast_pick(nt, look, r_color), by_lightness(facades))
        jitter = math_node(nt, "ADD", math_node(nt, "MULTIPLY", r_bright, 0.16), 0.92)
        bright = math_node(nt, "MULTIPLY", jitter, contrast_factor(nt, look, 0.7, 1.3))
    else:
        base = palette(nt, r_color, facades)
        bright = math_node(nt, "ADD", math_node(nt, "MULTIPLY", r_bright, 0.5), 0.75)
    uvw = node(nt, "ShaderNodeCombineXYZ")
    nt.links.new(t, uvw.inputs["X"])
    nt.links.new(height, uvw.inputs["Y"])
    brick = node(nt, "ShaderNodeTexBrick")
    brick.inputs["Scale"].default_value = 4.0
    brick.inputs["Mortar Size"].default_value = 0.015
    nt.links.new(uvw.outputs["Vector"], brick.inputs["Vector"])
    nt.links.new(base, brick.inputs["Color1"])
    brick.inputs["Color2"].default_value = (0.3, 0.12, 0.08, 1.0)
    brick.inputs["Mortar"].default_value = (0.6, 0.58, 0.55, 1.0)
    is_brick = math_node(nt, "LESS_THAN", r_style, 0.3)
    wall_color = mix_color(nt, is_brick, base, brick.outputs["Color"])
    # Plaster grime in facade coordinates (2D: walls are planes), features down to ~0.16 m.
    noise = node(nt, "ShaderNodeTexNoise", noise_dimensions="2D")
    noise.inputs["Scale"].default_value = 0.8
    noise.inputs["Detail"].default_value = 3.0
    nt.links.new(uvw.outputs["Vector"], noise.inputs["Vector"])
    grime = math_node(nt, "ADD", math_node(nt, "MULTIPLY", noise.outputs["Fac"], 0.5), 0.75)
    if look.get("wide_palette"):
        grime = weathering(nt, grime, t, height, bid, seed)
    shade = math_node(nt, "MULTIPLY", grime, bright)
    wall_scaled = node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="MULTIPLY", clamp_factor=True)
    socket(wall_scaled.inputs, "Factor_Float").default_value = 1.0
    nt.links.new(wall_color, socket(wall_scaled.inputs, "A_Color"))
    shade_rgb = node(nt, "ShaderNodeCombineXYZ")
    for k in ("X", "Y", "Z"):
        nt.links.new(shade, shade_rgb.inputs[k])
    nt.links.new(shade_rgb.outputs["Vector"], socket(wall_scaled.inputs, "B_Color"))
    wall_color = socket(wall_scaled.outputs, "Result_Color")

    glass = palette(nt, r_glass, GLASS_COLORS)
    color = mix_color(nt, window, wall_color, glass)
    if lighting == "direct":
        return direct_shader(nt, color, look, glass=window)
    return principled_shader(nt, color, mix_float(nt, window, 0.85, 0.06), mix_float(nt, window, 0.3, 1.0))


def weathering(nt, grime, t, height, bid, seed):
    """Vertical rain streaks (noise stretched 12× along the height), a per-building amount."""
    streak_uv = node(nt, "ShaderNodeCombineXYZ")
    nt.links.new(math_node(nt, "MULTIPLY", t, 1.5), streak_uv.inputs["X"])
    nt.links.new(math_node(nt, "MULTIPLY", height, 0.125), streak_uv.inputs["Y"])
    streaks = node(nt, "ShaderNodeTexNoise", noise_dimensions="2D")
    streaks.inputs["Scale"].default_value = 1.0
    streaks.inputs["Detail"].default_value = 1.0
    nt.links.new(streak_uv.outputs["Vector"], streaks.inputs["Vector"])
    weather = math_node(nt, "MULTIPLY", per_building_random(nt, bid, seed, 10), 0.6)
    dirt = math_node(nt, "MULTIPLY", math_node(nt, "GREATER_THAN", streaks.outputs["Fac"], 0.55), weather)
    grime = math_node(nt, "MULTIPLY", grime, math_node(nt, "SUBTRACT", 1.0, dirt))
    return grime


def roof_shader(nt, look, lighting, bid, seed, geo, pos):
    """Roofs: a palette colour with stains, and rooftop clutter (plant rooms, vents, solar panels) as
    Voronoi cells of ~6 m, a per-building share of which is lighter or darker than the membrane."""
    r_roof = per_building_random(nt, bid, seed, 6)
    if look.get("contrast"):
        roof_base = palette(nt, contrast_pick(nt, look, r_roof), by_lightness(ROOF_COLORS))
    else:
        roof_base = palette(nt, r_roof, ROOF_COLORS)
    # Roofs are (nearly) horizontal: 2D textures of plan position, features down to ~0.4 m.
    plan = node(nt, "ShaderNodeCombineXYZ")
    nt.links.new(pos.outputs["X"], plan.inputs["X"])
    nt.links.new(pos.outputs["Y"], plan.inputs["Y"])
    roof_noise = node(nt, "ShaderNodeTexNoise", noise_dimensions="2D")
    roof_noise.inputs["Scale"].default_value = 0.15
    roof_noise.inputs["Detail"].default_value = 4.0
    nt.links.new(plan.outputs["Vector"], roof_noise.inputs["Vector"])
    stained = mix_color(nt, math_node(nt, "MULTIPLY", roof_noise.outputs["Fac"], 0.5), roof_base,
                        (0.04, 0.04, 0.04, 1.0))
    cells = node(nt, "ShaderNodeTexVoronoi", voronoi_dimensions="2D", feature="F1", distance="CHEBYCHEV")
    cells.inputs["Scale"].default_value = 0.16
    nt.links.new(plan.outputs["Vector"], cells.inputs["Vector"])
    cell_rand = node(nt, "ShaderNodeSeparateColor")
    nt.links.new(cells.outputs["Color"], cell_rand.inputs["Color"])
    clutter = math_node(nt, "MULTIPLY", math_node(nt, "LESS_THAN", cell_rand.outputs["Red"], 0.18),
                        math_node(nt, "LESS_THAN", cells.outputs["Distance"], 0.28))
    clutter_color = mix_color(nt, cell_rand.outputs["Green"], (0.45, 0.45, 0.44, 1.0), (0.03, 0.04, 0.07, 1.0))
    color = mix_color(nt, clutter, stained, clutter_color)
    if look.get("wide_palette"):
        color = roof_kinds(nt, color, plan, roof_noise, bid, seed)
    if look.get("contrast"):
        # Green, metal and tile roofs ignore the band: scale every roof by its class (0.7 … 1.3).
        color = scale_color(nt, color, contrast_factor(nt, look, 0.7, 1.3))
    if lighting == "direct":
        return direct_shader(nt, color, look)
    return principled_shader(nt, color, 0.9, 0.3)


def roof_kinds(nt, color, plan, roof_noise, bid, seed):
    """Roof kinds beyond the membrane, per building: green (sedum) roofs, standing-seam metal and clay
    tile, the last two striped by one wave texture (a period of ~0.5 m: seams and tile rows)."""
    r_kind = per_building_random(nt, bid, seed, 9)
    waves = node(nt, "ShaderNodeTexWave", wave_type="BANDS", bands_direction="X")
    # Bands of sin(20·scale·x): a period of 2π / (20 · 0.6) ≈ 0.52 m.
    waves.inputs["Scale"].default_value = 0.6
    waves.inputs["Distortion"].default_value = 0.0
    nt.links.new(plan.outputs["Vector"], waves.inputs["Vector"])
    seam = math_node(nt, "GREATER_THAN", waves.outputs["Fac"], 0.8)
    # Low contrast: at 0.1–0.3 m per pixel the seams are sub-pixel and must not alias into stripes.
    metal = mix_color(nt, seam, (0.36, 0.39, 0.43, 1.0), (0.42, 0.45, 0.49, 1.0))
    tile = mix_color(nt, seam, (0.21, 0.068, 0.03, 1.0), (0.17, 0.055, 0.025, 1.0))
    green = mix_color(nt, roof_noise.outputs["Fac"], (0.03, 0.07, 0.02, 1.0), (0.12, 0.16, 0.04, 1.0))
    color = mix_color(nt, math_node(nt, "LESS_THAN", r_kind, 0.32), color, tile)
    color = mix_color(nt, math_node(nt, "LESS_THAN", r_kind, 0.2), color, metal)
    color = mix_color(nt, math_node(nt, "LESS_THAN", r_kind, 0.08), color, green)
    return color


def principled_shader(nt, color, roughness, specular):
    """The path-traced look's surface: a Principled BSDF (numbers or sockets for the parameters)."""
    bsdf = node(nt, "ShaderNodeBsdfPrincipled")
    link_or_set(nt, bsdf.inputs["Base Color"], color)
    link_or_set(nt, bsdf.inputs["Roughness"], roughness)
    link_or_set(nt, bsdf.inputs["Specular IOR Level"], specular)
    return bsdf.outputs["BSDF"]


def plain_surface(nt, mat, color, look, lighting, roughness, specular):
    """The surface of a material without glass (ground, appearances, clutter): the direct look's shader,
    whose emission Cycles must never sample, or the path-traced look's Principled BSDF."""
    if lighting == "direct":
        mat.cycles.emission_sampling = "NONE"
        return direct_shader(nt, color, look)
    return principled_shader(nt, color, roughness, specular)


# Direct lighting: the sky's contribution as constant colours (linear RGB per unit of sky strength). The
# ambient is what an overcast-free sky adds to every surface (bluish); the reflection is the sky seen in
# glass at grazing angles.
AMBIENT_PER_SKY = (0.5, 0.62, 0.8)
REFLECTION_PER_SKY = (1.2, 1.5, 2.0)


def direct_shader(nt, color, look, glass=None):
    """Lambertian surface lit by the sun, plus sky ambient (and a Fresnel sky reflection where `glass` is
    1) as emission; the material must set `emission_sampling = "NONE"` so that Cycles never samples it
    as a light: no stochastic term but anti-aliasing."""
    sky = float(look.get("sky_strength", 0.25))
    diffuse = node(nt, "ShaderNodeBsdfDiffuse")
    nt.links.new(color, diffuse.inputs["Color"])
    ambient = node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="MULTIPLY", clamp_factor=True)
    socket(ambient.inputs, "Factor_Float").default_value = 1.0
    nt.links.new(color, socket(ambient.inputs, "A_Color"))
    amb = node(nt, "ShaderNodeRGB")
    amb.outputs[0].default_value = (*(sky * c for c in AMBIENT_PER_SKY), 1.0)
    LIVE["ambient"].append(amb)
    nt.links.new(amb.outputs[0], socket(ambient.inputs, "B_Color"))
    glow = socket(ambient.outputs, "Result_Color")
    if glass is not None:
        fresnel = node(nt, "ShaderNodeLayerWeight")
        fresnel.inputs["Blend"].default_value = 1.0 - 1.0 / 1.5  # IOR 1.5
        weight = math_node(nt, "MULTIPLY", fresnel.outputs["Fresnel"], glass)
        add = node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="ADD", clamp_factor=True)
        nt.links.new(weight, socket(add.inputs, "Factor_Float"))
        nt.links.new(glow, socket(add.inputs, "A_Color"))
        refl = node(nt, "ShaderNodeRGB")
        refl.outputs[0].default_value = (*(sky * c for c in REFLECTION_PER_SKY), 1.0)
        LIVE["reflection"].append(refl)
        nt.links.new(refl.outputs[0], socket(add.inputs, "B_Color"))
        glow = socket(add.outputs, "Result_Color")
    emission = node(nt, "ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    nt.links.new(glow, emission.inputs["Color"])
    both = node(nt, "ShaderNodeAddShader")
    nt.links.new(diffuse.outputs["BSDF"], both.inputs[0])
    nt.links.new(emission.outputs["Emission"], both.inputs[1])
    return both.outputs["Shader"]


def ground_material(bpy, look, lighting):
    """Asphalt and grass patches from low-frequency noise, with fine grain, in plan coordinates (2D noise:
    the ground is a plane; the grain stops at ~0.2 m, the pixel footprint of a UAV view)."""
    mat, nt = new_material(bpy, "insgen_ground")
    out = node(nt, "ShaderNodeOutputMaterial")
    geo = node(nt, "ShaderNodeNewGeometry")
    # The seed moves the patch pattern: an offset in plan, far beyond any area's extent.
    seed = int(look["seed"]) % 1000
    offset = node(nt, "ShaderNodeVectorMath", operation="ADD")
    nt.links.new(geo.outputs["Position"], offset.inputs[0])
    offset.inputs[1].default_value = (1000.0 * seed, -700.0 * seed, 0.0)
    big = node(nt, "ShaderNodeTexNoise", noise_dimensions="2D")
    big.inputs["Scale"].default_value = 0.004
    big.inputs["Detail"].default_value = 3.0
    nt.links.new(offset.outputs["Vector"], big.inputs["Vector"])
    grass = math_node(nt, "GREATER_THAN", big.outputs["Fac"], 0.56)
    fine = node(nt, "ShaderNodeTexNoise", noise_dimensions="2D")
    fine.inputs["Scale"].default_value = 0.6
    fine.inputs["Detail"].default_value = 3.0
    nt.links.new(geo.outputs["Position"], fine.inputs["Vector"])
    asphalt = mix_color(nt, fine.outputs["Fac"], (0.05, 0.05, 0.05, 1.0), (0.16, 0.16, 0.15, 1.0))
    green = mix_color(nt, fine.outputs["Fac"], (0.03, 0.08, 0.02, 1.0), (0.10, 0.18, 0.05, 1.0))
    color = mix_color(nt, grass, asphalt, green)
    nt.links.new(plain_surface(nt, mat, color, look, lighting, 0.95, 0.5), out.inputs["Surface"])
    return mat


def id_material(bpy):
    """Flat emission: R = G = B = building ID (float32 holds every 24-bit integer exactly)."""
    mat, nt = new_material(bpy, "insgen_ids")
    out = node(nt, "ShaderNodeOutputMaterial")
    em = node(nt, "ShaderNodeEmission")
    em.inputs["Strength"].default_value = 1.0
    attr = node(nt, "ShaderNodeAttribute", attribute_type="GEOMETRY", attribute_name=FACE_ID_ATTRIBUTE)
    nt.links.new(attr.outputs["Color"], em.inputs["Color"])
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def emission_from_base_color(bpy, mat):
    """Shows a photogrammetry material's base colour unlit (the texture already holds the lighting)."""
    nt = mat.node_tree
    if nt is None:
        return
    principled = [n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"]
    outputs = [n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    if not principled or not outputs:
        return
    p = principled[0]
    em = nt.nodes.new("ShaderNodeEmission")
    base = p.inputs["Base Color"]
    if base.is_linked:
        nt.links.new(base.links[0].from_socket, em.inputs["Color"])
    else:
        em.inputs["Color"].default_value = base.default_value
    nt.links.new(em.outputs["Emission"], outputs[0].inputs["Surface"])
    # Texture-as-emission is not a light source: nothing to sample, no light tree to build per tile.
    mat.cycles.emission_sampling = "NONE"


def glb_appearance_materials(path):
    """The `asset.extras.appearance_materials` list of a scene.glb written by insgen ([] when absent or
    when the file is not a GLB): one {"texture": uri} or {"colour": [r, g, b]} per appearance number."""
    with open(path, "rb") as f:
        head = f.read(20)
        if len(head) < 20 or head[:4] != b"glTF" or head[16:20] != b"JSON":
            return []
        doc = json.loads(f.read(int.from_bytes(head[12:16], "little")))
    return doc.get("asset", {}).get("extras", {}).get("appearance_materials", [])


def appearance_material(bpy, entry, base_dir, look, lighting, number):
    """One source appearance lit like the procedural surfaces: its image through the mesh's UV map, or
    its flat colour. None when the image cannot be loaded (the faces keep the procedural look)."""
    mat, nt = new_material(bpy, f"insgen_appearance_{number}")
    out = node(nt, "ShaderNodeOutputMaterial")
    if "texture" in entry:
        path = os.path.join(base_dir, entry["texture"])
        try:
            image = bpy.data.images.load(path, check_existing=True)
        except RuntimeError as e:
            print(f"insgen: texture {path} cannot be loaded ({e}); its faces keep the procedural look",
                  file=sys.stderr)
            bpy.data.materials.remove(mat)
            return None
        tex = node(nt, "ShaderNodeTexImage", interpolation="Linear", extension="REPEAT")
        tex.image = image
        uv = node(nt, "ShaderNodeUVMap")
        nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
        color = tex.outputs["Color"]
    else:
        rgb = node(nt, "ShaderNodeRGB")
        rgb.outputs[0].default_value = (*[float(c) for c in entry["colour"]], 1.0)
        color = rgb.outputs[0]
    nt.links.new(plain_surface(nt, mat, color, look, lighting, 0.85, 0.3), out.inputs["Surface"])
    return mat


def apply_appearances(bpy, meshes, glb_path, look, lighting):
    """Textured and coloured faces of a LoD model show their source appearance: one material slot per
    appearance after the procedural slot 0, chosen per face from the _APPEARANCE attribute (its first
    corner's vertex, as for the building ID). Faces with appearance 0 keep the procedural look."""
    entries = glb_appearance_materials(glb_path)
    if not entries:
        return
    base_dir = os.path.dirname(os.path.abspath(glb_path))
    mats = [appearance_material(bpy, e, base_dir, look, lighting, k + 1) for k, e in enumerate(entries)]
    for obj in meshes:
        mesh = obj.data
        src = mesh.attributes.get(APPEARANCE_ATTRIBUTE)
        n_faces = len(mesh.polygons)
        if src is None or not n_faces:
            continue
        values = [0.0] * len(src.data)
        src.data.foreach_get("value", values)
        starts = [0] * n_faces
        mesh.polygons.foreach_get("loop_start", starts)
        if src.domain == "POINT":
            corner_verts = [0] * len(mesh.loops)
            mesh.loops.foreach_get("vertex_index", corner_verts)
            numbers = [int(round(values[corner_verts[s]])) for s in starts]
        elif src.domain == "CORNER":
            numbers = [int(round(values[s])) for s in starts]
        else:
            numbers = [int(round(v)) for v in values]
        # Slot k + 1 holds appearance k + 1; a material that could not be built maps to slot 0.
        slot_of = [0]
        for m in mats:
            if m is None:
                slot_of.append(0)
            else:
                mesh.materials.append(m)
                slot_of.append(len(mesh.materials) - 1)
        indices = [slot_of[k] if 0 <= k < len(slot_of) else 0 for k in numbers]
        mesh.polygons.foreach_set("material_index", indices)
        mesh.update()


def assign_material(meshes, mat):
    for obj in meshes:
        obj.data.materials.clear()
        obj.data.materials.append(mat)
        for poly in obj.data.polygons:
            poly.material_index = 0


def add_ground(bpy, scene, look, mat, half_extent_m):
    """A square plane at the ground level, 5 cm below it to stay clear of building floors."""
    from mathutils import Vector

    z = float(look["ground_enu_m"]) - 0.05
    cx, cy = look.get("ground_centre_enu_m", [0.0, 0.0])
    h = float(half_extent_m)
    mesh = bpy.data.meshes.new("insgen_ground")
    verts = [Vector((cx - h, cy - h, z)), Vector((cx + h, cy - h, z)), Vector((cx + h, cy + h, z)),
             Vector((cx - h, cy + h, z))]
    mesh.from_pydata(verts, [], [(0, 1, 2, 3)])
    mesh.materials.append(mat)
    obj = bpy.data.objects.new("insgen_ground", mesh)
    scene.collection.objects.link(obj)
    return obj


def sun_direction(look):
    """Unit vector towards the sun in ENU from azimuth (clockwise from north) and elevation, degrees."""
    az = math.radians(float(look["sun_azimuth_deg"]))
    el = math.radians(float(look["sun_elevation_deg"]))
    return (math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el))


def add_sky_and_sun(bpy, scene, look, lighting):
    from mathutils import Vector

    world = bpy.data.worlds.new("insgen_world")
    scene.world = world
    nt = world.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = node(nt, "ShaderNodeOutputWorld")
    bg = node(nt, "ShaderNodeBackground")
    sky = node(nt, "ShaderNodeTexSky")
    types = [e.identifier for e in sky.bl_rna.properties["sky_type"].enum_items]
    for wanted in ("MULTIPLE_SCATTERING", "SINGLE_SCATTERING", "NISHITA", "HOSEK_WILKIE"):
        if wanted in types:
            sky.sky_type = wanted
            break
    el = math.radians(float(look["sun_elevation_deg"]))
    az = math.radians(float(look["sun_azimuth_deg"]))
    if hasattr(sky, "sun_elevation"):
        sky.sun_elevation = el
        # Cycles places the sky's sun at azimuth sun_rotation + 90 deg counter-clockwise from +x, i.e.
        # rotation 0 = north; our azimuth runs clockwise from north.
        sky.sun_rotation = (-az) % (2.0 * math.pi)
        sky.sun_disc = False
    if hasattr(sky, "sun_direction"):
        sky.sun_direction = sun_direction(look)
    if hasattr(sky, "turbidity"):
        sky.turbidity = 2.5
    # The sky seen by the camera turns to the haze colour with the weather (apply_frame_look): sky × strength
    # mixed with a haze radiance, shown at strength 1.
    scaled = node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="MULTIPLY", clamp_factor=True)
    socket(scaled.inputs, "Factor_Float").default_value = 1.0
    nt.links.new(sky.outputs["Color"], socket(scaled.inputs, "A_Color"))
    strength = float(look.get("sky_strength", 0.25))
    socket(scaled.inputs, "B_Color").default_value = (strength, strength, strength, 1.0)
    hazed = node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="MIX", clamp_factor=True)
    socket(hazed.inputs, "Factor_Float").default_value = 0.0
    nt.links.new(socket(scaled.outputs, "Result_Color"), socket(hazed.inputs, "A_Color"))
    haze_rgb = node(nt, "ShaderNodeRGB")
    haze_rgb.outputs[0].default_value = (0.5, 0.55, 0.6, 1.0)
    nt.links.new(haze_rgb.outputs[0], socket(hazed.inputs, "B_Color"))
    nt.links.new(socket(hazed.outputs, "Result_Color"), bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 1.0
    nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
    LIVE["sky"] = sky
    LIVE["world_bg"] = socket(scaled.inputs, "B_Color")
    LIVE["world_mix"] = socket(hazed.inputs, "Factor_Float")
    LIVE["world_haze"] = haze_rgb

    light = bpy.data.lights.new("insgen_sun", type="SUN")
    light.energy = float(look.get("sun_strength", 4.0))
    # Direct lighting takes a point-like sun (hard shadows, one exact shadow ray); path tracing the real
    # disc (0.53 deg).
    light.angle = 0.0 if lighting == "direct" else math.radians(0.53)
    if lighting == "direct":
        # The sky is seen by the camera but lights nothing: its light is the materials' ambient term.
        vis = world.cycles_visibility
        vis.diffuse = vis.glossy = vis.transmission = vis.scatter = False
        world.cycles.sampling_method = "NONE"
    light.color = (1.0, 0.96, 0.9)
    sun = bpy.data.objects.new("insgen_sun", light)
    scene.collection.objects.link(sun)
    d = Vector(sun_direction(look))
    sun.rotation_mode = "QUATERNION"
    # A sun lamp shines along its local -Z: point -Z away from the sun.
    sun.rotation_quaternion = (-d).to_track_quat("-Z", "Y")
    LIVE["sun"] = sun


def black_world(bpy, scene):
    world = bpy.data.worlds.new("insgen_black")
    scene.world = world
    nt = world.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = node(nt, "ShaderNodeOutputWorld")
    bg = node(nt, "ShaderNodeBackground")
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 0.0
    nt.links.new(bg.outputs["Background"], out.inputs["Surface"])


def add_haze(bpy, mat):
    """Distance haze on a material: its surface shader mixed with the haze radiance by 1 − exp(−β·d), d
    the distance from the camera (Koschmieder: β = 3 / visibility). β = 0 (no haze) gives a Mix Shader
    weight of exactly 0, which Cycles skips."""
    nt = mat.node_tree
    if nt is None:
        return
    outs = [n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    if not outs or not outs[0].inputs["Surface"].is_linked:
        return
    out = outs[0]
    surface = out.inputs["Surface"].links[0].from_socket
    cam = node(nt, "ShaderNodeCameraData")
    beta = node(nt, "ShaderNodeValue")
    beta.outputs[0].default_value = 0.0
    LIVE["haze_beta"].append(beta)
    # 1 − exp(−β·d)
    optical = math_node(nt, "MULTIPLY", cam.outputs["View Distance"], beta.outputs[0])
    fac = math_node(nt, "SUBTRACT", 1.0, math_node(nt, "EXPONENT", math_node(nt, "MULTIPLY", optical, -1.0)))
    color = node(nt, "ShaderNodeRGB")
    color.outputs[0].default_value = (0.5, 0.55, 0.6, 1.0)
    LIVE["haze_color"].append(color)
    em = node(nt, "ShaderNodeEmission")
    em.inputs["Strength"].default_value = 1.0
    nt.links.new(color.outputs[0], em.inputs["Color"])
    mix = node(nt, "ShaderNodeMixShader")
    nt.links.new(fac, mix.inputs["Fac"])
    nt.links.new(surface, mix.inputs[1])
    nt.links.new(em.outputs["Emission"], mix.inputs[2])
    nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    # The haze's light is already integrated: never a light source to sample.
    mat.cycles.emission_sampling = "NONE"


def apply_frame_look(scene, job, look):
    """Sets one frame's sun, sky, haze and exposure (the values drawn by insgen, src/blender/look.rs)."""
    from mathutils import Vector

    scene.view_settings.exposure = float(job["look"].get("exposure", 0.0)) + float(look.get("exposure_ev", 0.0))
    sun = LIVE["sun"]
    if sun is None:
        # Unlit photogrammetry or Workbench: only haze and exposure apply.
        sun_level = 1.0
    else:
        d = Vector(sun_direction(look))
        sun.rotation_quaternion = (-d).to_track_quat("-Z", "Y")
        sun.data.energy = float(look["sun_strength"])
        sun_level = float(look["sun_strength"]) * max(d.z, 0.0) / math.pi
    sky_kind = look.get("sky", "clear")
    sky = float(look["sky_strength"])
    amb = AMBIENT_BY_SKY.get(sky_kind, AMBIENT_PER_SKY)
    for n in LIVE["ambient"]:
        n.outputs[0].default_value = (*(sky * c for c in amb), 1.0)
    for n in LIVE["reflection"]:
        n.outputs[0].default_value = (*(sky * c for c in REFLECTION_PER_SKY), 1.0)
    # The haze is as bright as a white surface under this light (the air scatters sun and sky).
    white = sun_level + sky * 0.65 if sun is not None else 0.8
    haze = tuple(float(c) * white for c in look.get("haze_rgb", (0.0, 0.0, 0.0)))
    visibility = look.get("visibility_m")
    beta = 3.0 / float(visibility) if visibility else 0.0
    for n in LIVE["haze_beta"]:
        n.outputs[0].default_value = beta
    for n in LIVE["haze_color"]:
        n.outputs[0].default_value = (*haze, 1.0)
    sky_node = LIVE["sky"]
    if sky_node is not None:
        el = math.radians(float(look["sun_elevation_deg"]))
        az = math.radians(float(look["sun_azimuth_deg"]))
        if hasattr(sky_node, "sun_elevation"):
            sky_node.sun_elevation = el
            sky_node.sun_rotation = (-az) % (2.0 * math.pi)
        if hasattr(sky_node, "sun_direction"):
            sky_node.sun_direction = sun_direction(look)
        if hasattr(sky_node, "turbidity"):
            sky_node.turbidity = SKY_TURBIDITY.get(sky_kind, 2.5)
        LIVE["world_bg"].default_value = (sky, sky, sky, 1.0)
        LIVE["world_mix"].default_value = SKY_HAZE_MIX.get(sky_kind, 0.0) if visibility else 0.0
        # A hazy or overcast sky is brighter than the ground's haze.
        LIVE["world_haze"].outputs[0].default_value = (*(1.5 * c for c in haze), 1.0)


# ------------------------------------------------------------------------------------------- clutter
# The scene GLB's clutter layers (src/scene/clutter.rs): one node per layer named insgen_clutter_<layer>
# (node extras insgen_layer = <layer>), triangles with a per-vertex sRGB colour in COLOR_0 and no building
# IDs, so the ID render draws them as background (0) and they hide what is behind them.

CLUTTER_PREFIX = "insgen_clutter_"
# Per layer: scale of the grain noise (1/m; 0 = none) and its contrast, and the path-traced roughness.
CLUTTER_LOOKS = {
    "roads": (0.9, 0.35, 0.9),
    "markings": (0.0, 0.0, 0.6),
    "pavements": (1.6, 0.25, 0.85),
    "ground_cover": (0.35, 0.5, 0.95),
    "trees": (1.8, 0.6, 0.9),
    "cars": (0.0, 0.0, 0.3),
    "rooftop": (0.0, 0.0, 0.5),
}


def clutter_layer(obj):
    """The clutter layer of an imported object, or None for a building mesh."""
    layer = obj.get("insgen_layer") if hasattr(obj, "get") else None
    if layer is None and obj.name.startswith(CLUTTER_PREFIX):
        layer = obj.name[len(CLUTTER_PREFIX):].split(".")[0]
    return layer


def clutter_material(bpy, layer, look, lighting, color_attribute):
    """Vertex colour (sRGB bytes in COLOR_0, taken to linear with gamma 2.2) with a grain noise per layer;
    the same cheap direct-lighting shader as the buildings, or a Principled BSDF when path tracing."""
    grain_scale, grain_amount, roughness = CLUTTER_LOOKS.get(layer, (0.0, 0.0, 0.8))
    mat, nt = new_material(bpy, f"{CLUTTER_PREFIX}{layer}")
    out = node(nt, "ShaderNodeOutputMaterial")
    attr = node(nt, "ShaderNodeVertexColor", layer_name=color_attribute or "")
    gamma = node(nt, "ShaderNodeGamma")
    nt.links.new(attr.outputs["Color"], gamma.inputs["Color"])
    gamma.inputs["Gamma"].default_value = 2.2
    color = gamma.outputs["Color"]
    if grain_scale > 0.0:
        geo = node(nt, "ShaderNodeNewGeometry")
        noise = node(nt, "ShaderNodeTexNoise", noise_dimensions="3D")
        noise.inputs["Scale"].default_value = grain_scale
        noise.inputs["Detail"].default_value = 2.0
        nt.links.new(geo.outputs["Position"], noise.inputs["Vector"])
        # Brightness between 1 - amount and 1 + amount/2 around the vertex colour.
        lo = math_node(nt, "MULTIPLY", noise.outputs["Fac"], 1.5 * grain_amount)
        fac = math_node(nt, "ADD", lo, 1.0 - 0.75 * grain_amount)
        scale = node(nt, "ShaderNodeMix", data_type="RGBA", blend_type="MULTIPLY", clamp_factor=True)
        socket(scale.inputs, "Factor_Float").default_value = 1.0
        nt.links.new(color, socket(scale.inputs, "A_Color"))
        combine = node(nt, "ShaderNodeCombineColor")
        for ch in ("Red", "Green", "Blue"):
            nt.links.new(fac, combine.inputs[ch])
        nt.links.new(combine.outputs["Color"], socket(scale.inputs, "B_Color"))
        color = socket(scale.outputs, "Result_Color")
    nt.links.new(plain_surface(nt, mat, color, look, lighting, roughness, 0.5), out.inputs["Surface"])
    return mat


def apply_clutter(bpy, job, placed):
    """RGB mode: each clutter layer gets its material. IDs mode: layers not listed in the job's
    `clutter_occluders` are deleted; the rest keep the ID material and its face ID 0 (no
    _FEATURE_ID_0), i.e. background that hides the buildings behind it."""
    look = job["look"]
    keep = job.get("clutter_occluders")
    materials = {}
    for index, (root, meshes, model) in enumerate(placed):
        kept = []
        for obj in meshes:
            layer = clutter_layer(obj)
            if layer is None:
                kept.append(obj)
            elif job["mode"] == "ids":
                if keep is None or layer in keep:
                    kept.append(obj)
                else:
                    bpy.data.objects.remove(obj, do_unlink=True)
            else:
                kept.append(obj)
                if job["engine"] == "workbench":
                    continue
                if layer not in materials:
                    attrs = getattr(obj.data, "color_attributes", None)
                    name = attrs[0].name if attrs is not None and len(attrs) else ""
                    materials[layer] = clutter_material(bpy, layer, look, job["lighting"], name)
                assign_material([obj], materials[layer])
        placed[index] = (root, kept, model)


def build_look(bpy, scene, job, placed):
    look = job["look"]
    if job["mode"] == "ids":
        mat = id_material(bpy)
        for _root, meshes, _model in placed:
            assign_material(meshes, mat)
        apply_clutter(bpy, job, placed)
        black_world(bpy, scene)
        return
    if job["engine"] == "workbench":
        # Workbench shows the models' colour attribute (the scene's flat per-building colour).
        scene.world = bpy.data.worlds.new("insgen_world")
        return
    lighting = job["lighting"]
    # The varied look (per-frame weather, src/blender/look.rs) also widens the material palette.
    look = dict(look, wide_palette=any(f.get("look", {}).get("style") == "varied" for f in job["frames"]))
    bmat = building_material(bpy, look, lighting)
    for _root, meshes, model in placed:
        if model["kind"] == "lod":
            assign_material(meshes, bmat)
            apply_appearances(bpy, meshes, model["glb"], look, lighting)
        else:
            for obj in meshes:
                for slot in obj.material_slots:
                    if slot.material is not None:
                        emission_from_base_color(bpy, slot.material)
    apply_clutter(bpy, job, placed)
    if look.get("ground_plane", True):
        add_ground(bpy, scene, look, ground_material(bpy, look, lighting), look.get("ground_half_extent_m", 20000.0))
    add_sky_and_sun(bpy, scene, look, lighting)
    # Distance haze on every surface (buildings, ground, tiles, and any other layer's materials).
    if any(f.get("look", {}).get("visibility_m") for f in job["frames"]):
        for mat in list(bpy.data.materials):
            if mat.users > 0 and mat.node_tree is not None:
                add_haze(bpy, mat)


# --------------------------------------------------------------------------------------------- frames


def make_camera(bpy, scene):
    cam_data = bpy.data.cameras.new("insgen_camera")
    cam = bpy.data.objects.new("insgen_camera", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    return cam


def apply_camera(scene, cam, frame):
    """Sets resolution, pixel aspect and the camera exactly as the job derived them (src/blender/camera.rs)."""
    from mathutils import Matrix

    k = frame["intrinsics"]
    b = frame["camera"]
    r = scene.render
    r.resolution_x = int(k["width_px"])
    r.resolution_y = int(k["height_px"])
    r.pixel_aspect_x = float(b["pixel_aspect_x"])
    r.pixel_aspect_y = float(b["pixel_aspect_y"])
    d = cam.data
    d.type = "PERSP"
    d.lens_unit = "MILLIMETERS"
    d.sensor_fit = "HORIZONTAL"
    d.sensor_width = float(b["sensor_width_mm"])
    d.lens = float(b["lens_mm"])
    d.shift_x = float(b["shift_x"])
    d.shift_y = float(b["shift_y"])
    d.clip_start = float(b["clip_start_m"])
    d.clip_end = float(b["clip_end_m"])
    cam.matrix_world = Matrix(frame["blender_matrix_world"])


def set_visibility(placed, frame):
    visible = frame.get("models")
    for index, (_root, meshes, _model) in enumerate(placed):
        hide = visible is not None and index not in visible
        for obj in meshes:
            # Only real changes: any assignment tags the object, and Cycles then rebuilds the whole BVH
            # (measured: +0.45 s per 1920x1080 Shibuya frame when nothing else changes).
            if obj.hide_render != hide:
                obj.hide_render = hide


def prepare_frame(scene, cam, placed, job, frame, applied_look):
    """Sets the camera, the visible models and (RGB) the frame's drawn look; returns the look now set.
    Setting even unchanged values makes Cycles rebuild its BVH, so a look equal to `applied_look` (the
    previous frame's, e.g. --look plain) is not set again."""
    apply_camera(scene, cam, frame)
    set_visibility(placed, frame)
    if job["mode"] == "rgb" and job["engine"] == "cycles" and "look" in frame:
        if frame["look"] != applied_look:
            apply_frame_look(scene, job, frame["look"])
        return frame["look"]
    return applied_look


def save(bpy, scene, frame, mode):
    img = bpy.data.images["Render Result"]
    s = scene.render.image_settings
    if frame.get("png"):
        s.file_format = "PNG"
        s.color_mode = "RGB"
        s.color_depth = "8"
        s.compression = 15
        img.save_render(frame["png"], scene=scene)
    if frame.get("exr"):
        s.file_format = "OPEN_EXR"
        s.color_mode = "RGB"
        s.color_depth = "32"
        s.exr_codec = "ZIP"
        img.save_render(frame["exr"], scene=scene)


def main(argv):
    started = time.time()
    job_path = job_path_from_argv(argv)
    job = load_job(job_path)
    try:
        import bpy  # noqa: F401  (imported here so a missing bpy is reported with the job path)
    except ImportError as e:
        emit({"error": f"cannot import bpy: {e}", "frame": None})
        sys.stderr.write(f"ModuleNotFoundError: No module named 'bpy' ({e})\n")
        return 3
    scene = reset_scene(bpy)
    device = configure_render(bpy, scene, job)
    placed = import_models(bpy, job)
    build_look(bpy, scene, job, placed)
    cam = make_camera(bpy, scene)
    ready = {"models": len(placed), "seconds": round(time.time() - started, 3), "device": device,
             "blender": bpy.app.version_string}
    if job.get("report_bounds"):
        ready["bounds"] = model_bounds(placed)
    emit({"ready": ready})
    current = None
    applied_look = None
    try:
        for frame in job["frames"]:
            current = frame["name"]
            t0 = time.time()
            c0 = time.process_time()
            applied_look = prepare_frame(scene, cam, placed, job, frame, applied_look)
            bpy.ops.render.render(write_still=False)
            save(bpy, scene, frame, job["mode"])
            emit({"done": current, "seconds": round(time.time() - t0, 3),
                  "cpu_seconds": round(time.process_time() - c0, 3)})
    except Exception as e:  # reported with the frame, then the traceback for the log
        emit({"error": f"{type(e).__name__}: {e}", "frame": current})
        traceback.print_exc()
        return 1
    return 0


if __name__ == "__main__":
    try:
        code = main(sys.argv)
    except SystemExit:
        raise
    except Exception as e:
        emit({"error": f"{type(e).__name__}: {e}", "frame": None})
        traceback.print_exc()
        code = 1
    sys.stdout.flush()
    sys.exit(code)
