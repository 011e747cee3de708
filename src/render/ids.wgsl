// Instance-ID pass: every fragment writes the 24-bit building ID of its triangle (flat, no blending)
// and, optionally, its depth along the optical axis in metres.
//
// Camera-relative transform (see view.rs): positions arrive as f32 ENU metres relative to the area
// origin; the camera centre is passed as an f32 pair (hi + lo == the f64 centre to ~1e-9 relative), so
// `(p - hi) - lo` is the offset from the camera with rounding relative to the camera distance, not to the
// distance from the origin. The rotation and the pinhole projection were built in f64 on the CPU.

struct View {
    // Rows of R_cam_from_world (OpenCV camera axes); w unused.
    r0: vec4<f32>,
    r1: vec4<f32>,
    r2: vec4<f32>,
    // Camera centre in ENU metres, split as hi + lo; w unused.
    centre_hi: vec4<f32>,
    centre_lo: vec4<f32>,
    // Pinhole: clip.x = ax * x + bx * z, clip.y = ay * y + by * z (see view.rs for the derivation).
    proj: vec4<f32>,
    // Reversed-Z: clip.z = za * z + zb, so depth = 1 at the near plane and 0 at the far plane.
    // (za, zb, near_m, far_m)
    depth: vec4<f32>,
};

@group(0) @binding(0) var<uniform> view: View;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) building_id: u32,
    // Camera-frame z in metres; perspective-correct interpolation of an affine quantity is exact.
    @location(1) z_m: f32,
};

@vertex
fn vs_main(@location(0) position_m: vec3<f32>, @location(1) building_id: u32) -> VsOut {
    let d = (position_m - view.centre_hi.xyz) - view.centre_lo.xyz;
    let c = vec3<f32>(dot(view.r0.xyz, d), dot(view.r1.xyz, d), dot(view.r2.xyz, d));
    var out: VsOut;
    out.clip = vec4<f32>(
        view.proj.x * c.x + view.proj.y * c.z,
        view.proj.z * c.y + view.proj.w * c.z,
        view.depth.x * c.z + view.depth.y,
        c.z,
    );
    out.building_id = building_id;
    out.z_m = c.z;
    return out;
}

@fragment
fn fs_ids(in: VsOut) -> @location(0) u32 {
    return in.building_id;
}

struct IdsDepth {
    @location(0) building_id: u32,
    @location(1) depth_m: f32,
};

@fragment
fn fs_ids_depth(in: VsOut) -> IdsDepth {
    var out: IdsDepth;
    out.building_id = in.building_id;
    out.depth_m = in.z_m;
    return out;
}
