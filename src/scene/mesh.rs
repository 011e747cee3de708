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

/// One building on its own: its 24-bit ID and its triangles (three vertices each) in ENU metres, as
/// the generated tilesets and the photogrammetry simulation take them.
#[derive(Debug, Clone, PartialEq)]
pub struct CityBuilding {
    /// The building's ID.
    pub id: BuildingId,
    /// Vertex positions, ENU metres relative to the area origin.
    pub positions_enu_m: Vec<[f64; 3]>,
    /// Triangles as indices into `positions_enu_m`.
    pub triangles: Vec<[u32; 3]>,
}

/// Splits a prepared scene mesh into its buildings (in ID order; each triangle gets its own three
/// vertices).
pub fn buildings_from_scene(mesh: &SceneMesh) -> Vec<CityBuilding> {
    let mut by_id: std::collections::BTreeMap<BuildingId, CityBuilding> = Default::default();
    for t in mesh.indices.chunks_exact(3) {
        let id = mesh.building_ids[t[0] as usize];
        let b = by_id.entry(id).or_insert_with(|| CityBuilding {
            id,
            positions_enu_m: vec![],
            triangles: vec![],
        });
        let base = b.positions_enu_m.len() as u32;
        for &i in t {
            b.positions_enu_m.push(mesh.positions_m[i as usize].map(f64::from));
        }
        b.triangles.push([base, base + 1, base + 2]);
    }
    by_id.into_values().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_mesh_splits_into_buildings() {
        let mesh = SceneMesh {
            positions_m: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [5.0, 0.0, 0.0],
                [6.0, 0.0, 0.0],
                [5.0, 1.0, 2.0],
            ],
            building_ids: [7, 7, 7, 3, 3, 3].map(|i| BuildingId::new(i).unwrap()).to_vec(),
            indices: vec![0, 1, 2, 3, 4, 5, 2, 1, 0],
        };
        let b = buildings_from_scene(&mesh);
        assert_eq!(
            b.iter().map(|b| (b.id.get(), b.triangles.len())).collect::<Vec<_>>(),
            vec![(3, 1), (7, 2)]
        );
        assert_eq!(b[0].positions_enu_m[2], [5.0, 1.0, 2.0]);
        assert_eq!(b[1].triangles[1], [3, 4, 5]);
    }
}
