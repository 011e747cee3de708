// Pixel count of one building ID inside a rectangle of an R32Uint ID map, for the "rendered alone"
// (amodal) coverage behind `visible_fraction`. One slot per building; the slot is bound with a dynamic
// offset, so one bind group serves a whole batch.

struct Slot {
    building_id: u32,
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
    count: atomic<u32>,
};

@group(0) @binding(0) var ids: texture_2d<u32>;
@group(0) @binding(1) var<storage, read_write> slot: Slot;

// Per-workgroup partial count (workgroup memory starts zeroed), so the global counter sees one atomic
// per workgroup instead of one per pixel.
var<workgroup> local_count: atomic<u32>;

@compute @workgroup_size(16, 16)
fn count_id(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let w = slot.w;
    let h = slot.h;
    if gid.x < w && gid.y < h {
        let p = vec2<u32>(slot.x0 + gid.x, slot.y0 + gid.y);
        if textureLoad(ids, p, 0).r == slot.building_id {
            atomicAdd(&local_count, 1u);
        }
    }
    workgroupBarrier();
    if li == 0u {
        let c = atomicLoad(&local_count);
        if c > 0u {
            atomicAdd(&slot.count, c);
        }
    }
}
