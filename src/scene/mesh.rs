//! The instanced scene mesh: what the renderers consume.
//!
//! Positions are f32 ENU metres relative to the area origin (small numbers, so f32 is exact to well
//! under a millimetre within tens of kilometres); every vertex carries the 24-bit building ID of the
//! triangle it belongs to (buildings never share vertices), so a flat-interpolated ID reaches the
//! fragment shader unchanged.

use super::ids::BuildingId;

/// A triangle soup with per-vertex building IDs, in the area's ENU frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SceneMesh {
    /// Vertex positions in ENU metres relative to the area origin.
    pub positions_m: Vec<[f32; 3]>,
    /// Building ID (never the background) of each vertex.
    pub building_ids: Vec<BuildingId>,
    /// Triangle vertex indices.
    pub indices: Vec<u32>,
}

impl SceneMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Axis-aligned bounds (min, max) of all vertices, or `None` for an empty mesh.
    pub fn bounds_m(&self) -> Option<([f32; 3], [f32; 3])> {
        let mut it = self.positions_m.iter();
        let first = *it.next()?;
        let (mut lo, mut hi) = (first, first);
        for p in it {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        Some((lo, hi))
    }

    /// The sub-mesh of the buildings for which `keep(id)` holds (used to cull to buildings near a pose).
    pub fn filter_buildings(&self, keep: impl Fn(BuildingId) -> bool) -> SceneMesh {
        let mut out = SceneMesh::default();
        let mut remap = vec![u32::MAX; self.positions_m.len()];
        for tri in self.indices.chunks_exact(3) {
            if !keep(self.building_ids[tri[0] as usize]) {
                continue;
            }
            for &v in tri {
                let v = v as usize;
                if remap[v] == u32::MAX {
                    remap[v] = out.positions_m.len() as u32;
                    out.positions_m.push(self.positions_m[v]);
                    out.building_ids.push(self.building_ids[v]);
                }
                out.indices.push(remap[v]);
            }
        }
        out
    }
}
