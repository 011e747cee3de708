//! The scene mesh on the GPU: one vertex buffer (f32 ENU position + building ID) and one index buffer
//! whose triangles are grouped by building, so one building can be drawn alone (the amodal coverage
//! behind `visible_fraction`) without uploading a filtered copy of the mesh.

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use super::error::MeshProblem;
use super::RenderError;
use crate::scene::{BuildingId, SceneMesh};

/// One vertex as the shader reads it: `@location(0)` position, `@location(1)` building ID.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuVertex {
    /// ENU metres relative to the area origin.
    pub position_m: [f32; 3],
    /// 24-bit building ID (1..=2²⁴ − 1).
    pub building_id: u32,
}

impl GpuVertex {
    /// The vertex buffer layout matching `vs_main` in `ids.wgsl`.
    pub const LAYOUT: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<GpuVertex>() as wgpu::BufferAddress,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Uint32],
    };
}

/// Where one building's triangles sit in the index buffer, and its bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BuildingRange {
    /// The building.
    pub building_id: BuildingId,
    /// First index and number of indices (3 per triangle) in the index buffer.
    pub first_index: u32,
    /// Number of indices (3 per triangle).
    pub index_count: u32,
    /// Axis-aligned bounds of its vertices, ENU metres relative to the area origin.
    pub min_m: [f32; 3],
    /// Upper corner of the bounds, ENU metres.
    pub max_m: [f32; 3],
}

/// A [`SceneMesh`] uploaded once and drawn by every frame.
#[derive(Debug)]
pub struct GpuScene {
    pub(crate) vertices: wgpu::Buffer,
    pub(crate) indices: wgpu::Buffer,
    pub(crate) index_count: u32,
    /// Ordered by building ID.
    buildings: Vec<BuildingRange>,
    /// Triangles with ID 0 (occluders).
    occluder_triangles: u32,
}

impl GpuScene {
    /// Validates `mesh` and uploads it. Triangles are reordered by building ID (stable, so the draw order
    /// and therefore the winner of exact depth ties — coplanar shared walls — is the lower building ID,
    /// deterministically).
    ///
    /// # Errors
    /// [`RenderError::InvalidMesh`] when buffers disagree in length, an index is out of range, a
    /// coordinate is not finite, or a triangle's vertices carry different building IDs (the
    /// flat-interpolated ID would then depend on the provoking vertex).
    ///
    /// Triangles whose ID is the background's (0) are *occluders* (clutter: trees, cars, …): they are
    /// drawn with the buildings, depth-tested, and write 0, so they hide what is behind them; they are
    /// not listed in [`GpuScene::buildings`] and never drawn alone.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        mesh: &SceneMesh,
    ) -> Result<GpuScene, RenderError> {
        let _ = queue; // buffers are created initialised; the queue is taken for symmetry with the rest
        let bad = |problem: MeshProblem| Err(RenderError::InvalidMesh(problem));
        if mesh.positions_m.len() != mesh.building_ids.len() {
            return bad(MeshProblem::Lengths {
                positions: mesh.positions_m.len(),
                building_ids: mesh.building_ids.len(),
            });
        }
        if !mesh.indices.len().is_multiple_of(3) {
            return bad(MeshProblem::IndexCount { indices: mesh.indices.len() });
        }
        if mesh.indices.len() > u32::MAX as usize || mesh.positions_m.len() > u32::MAX as usize {
            return bad(MeshProblem::TooLarge {
                indices: mesh.indices.len(),
                vertices: mesh.positions_m.len(),
            });
        }
        if let Some((v, p)) =
            mesh.positions_m.iter().enumerate().find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return bad(MeshProblem::NonFinite { vertex: v, position_m: *p });
        }
        let n_vertices = mesh.positions_m.len();
        let mut tri_ids = Vec::with_capacity(mesh.triangle_count());
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i as usize >= n_vertices) {
                return bad(MeshProblem::VertexIndex { triangle: t, vertex: i, vertices: n_vertices });
            }
            let ids = [tri[0], tri[1], tri[2]].map(|i| mesh.building_ids[i as usize]);
            if ids[0] != ids[1] || ids[0] != ids[2] {
                if ids.iter().any(|id| id.is_background()) {
                    return bad(MeshProblem::MixedOccluder { triangle: t, ids });
                }
                return bad(MeshProblem::MixedBuildings { triangle: t, ids });
            }
            tri_ids.push(ids[0]);
        }
        // Stable sort of triangles by building ID.
        let mut order: Vec<u32> = (0..tri_ids.len() as u32).collect();
        order.sort_by_key(|&t| tri_ids[t as usize]);
        let mut indices = Vec::with_capacity(mesh.indices.len());
        let mut buildings: Vec<BuildingRange> = Vec::new();
        for &t in &order {
            let id = tri_ids[t as usize];
            let tri = &mesh.indices[3 * t as usize..3 * t as usize + 3];
            if buildings.last().map(|b| b.building_id) != Some(id) {
                let p = mesh.positions_m[tri[0] as usize];
                buildings.push(BuildingRange {
                    building_id: id,
                    first_index: indices.len() as u32,
                    index_count: 0,
                    min_m: p,
                    max_m: p,
                });
            }
            // The last entry exists: it was pushed just above when the ID changed.
            let b = buildings.last_mut().expect("a range was pushed for this building");
            for &i in tri {
                let p = mesh.positions_m[i as usize];
                for (k, &c) in p.iter().enumerate() {
                    b.min_m[k] = b.min_m[k].min(c);
                    b.max_m[k] = b.max_m[k].max(c);
                }
            }
            b.index_count += 3;
            indices.extend_from_slice(tri);
        }
        // Occluders (ID 0) sort first; they are drawn with everything but are no building.
        let occluder_triangles = match buildings.first() {
            Some(b) if b.building_id.is_background() => buildings.remove(0).index_count / 3,
            _ => 0,
        };
        let vertices: Vec<GpuVertex> = mesh
            .positions_m
            .iter()
            .zip(&mesh.building_ids)
            .map(|(&position_m, &building_id)| GpuVertex { position_m, building_id: building_id.get() })
            .collect();
        // wgpu buffers may not be empty-bound; an empty scene still gets a (never drawn) 16-byte buffer.
        let mut vertex_bytes = bytemuck::cast_slice::<GpuVertex, u8>(&vertices).to_vec();
        vertex_bytes.resize(vertex_bytes.len().max(16), 0);
        let mut index_bytes = bytemuck::cast_slice::<u32, u8>(&indices).to_vec();
        index_bytes.resize(index_bytes.len().max(16), 0);
        let vertex_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("scene vertices (ENU m f32 + building id)"),
            contents: &vertex_bytes,
            usage: wgpu::BufferUsages::VERTEX,
        });
        let index_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("scene indices (grouped by building)"),
            contents: &index_bytes,
            usage: wgpu::BufferUsages::INDEX,
        });
        log::debug!(
            "uploaded scene: {} vertices, {} triangles, {} buildings",
            n_vertices,
            indices.len() / 3,
            buildings.len()
        );
        Ok(GpuScene {
            vertices: vertex_buffer,
            indices: index_buffer,
            index_count: indices.len() as u32,
            buildings,
            occluder_triangles,
        })
    }

    /// Number of triangles uploaded.
    pub fn triangle_count(&self) -> u32 {
        self.index_count / 3
    }

    /// Triangles of occluders (ID 0: clutter drawn into the depth test as background).
    pub fn occluder_triangles(&self) -> u32 {
        self.occluder_triangles
    }

    /// The buildings in the scene, ordered by ID (occluders are not listed).
    pub fn buildings(&self) -> &[BuildingRange] {
        &self.buildings
    }

    /// The index range and bounds of one building, if it is in the scene.
    pub fn building(&self, building_id: BuildingId) -> Option<&BuildingRange> {
        self.buildings.binary_search_by_key(&building_id, |b| b.building_id).ok().map(|i| &self.buildings[i])
    }
}
