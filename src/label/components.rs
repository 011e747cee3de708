//! Connected components of an instance-ID map (the paper's "Connected Component Analysis").
//!
//! Two pixels belong to the same component when they carry the same non-zero building ID and are
//! neighbours (4- or 8-connectivity). Components are numbered in raster order of their first pixel
//! (row-major, top-left first), and per building in the same order, so labelling is deterministic.
//!
//! The algorithm is the classic two-pass union-find over rows; it is linear in the pixel count.

use serde::{Deserialize, Serialize};

use crate::scene::{BuildingId, IdMap};

/// Pixel neighbourhood for connectivity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Connectivity {
    /// Edge neighbours only.
    #[serde(rename = "4")]
    Four,
    /// Edge and corner neighbours (default: a building's diagonal-touching pixels stay one instance).
    #[default]
    #[serde(rename = "8")]
    Eight,
}

/// One connected component.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Component {
    /// The building the component belongs to.
    pub building_id: BuildingId,
    /// Index of this component among its building's components (raster order of first pixel).
    pub index: u32,
    /// Pixels in the component.
    pub area_px: u64,
    /// Bounding box [x, y, w, h] in pixels.
    pub bbox_px: [u32; 4],
    /// Whether the component touches the image border (the building may continue outside the frame).
    pub touches_border: bool,
}

/// The result of labelling: a component label per pixel (0 = background, k = `components[k − 1]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Labelling {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Component label per pixel, row-major (0 = background, k = `components[k − 1]`).
    pub labels: Vec<u32>,
    /// The components, in raster order of their first pixel.
    pub components: Vec<Component>,
}

impl Labelling {
    /// The binary mask (row-major, one byte per pixel, 1 inside) of component `k` (0-based).
    pub fn mask(&self, k: usize) -> Vec<u8> {
        let label = k as u32 + 1;
        self.labels.iter().map(|&l| (l == label) as u8).collect()
    }
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[x as usize];
        parent[x as usize] = parent[p as usize];
        x = p;
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        // Keep the smaller (earlier) root so roots are first pixels in raster order.
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        parent[hi as usize] = lo;
    }
}

/// Labels the connected components of the buildings in `map`.
pub fn label_components(map: &IdMap, connectivity: Connectivity) -> Labelling {
    let (width, height) = (map.width(), map.height());
    let (w, h) = (width as usize, height as usize);
    let ids = map.ids();
    // Provisional labels: the pixel index of the run's representative, u32::MAX for background.
    let mut prov = vec![u32::MAX; w * h];
    let mut parent: Vec<u32> = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let id = ids[i];
            if id.is_background() {
                continue;
            }
            let mut label = u32::MAX;
            let mut neighbours = [usize::MAX; 4];
            if x > 0 {
                neighbours[0] = i - 1;
            }
            if y > 0 {
                neighbours[1] = i - w;
                if connectivity == Connectivity::Eight {
                    if x > 0 {
                        neighbours[2] = i - w - 1;
                    }
                    if x + 1 < w {
                        neighbours[3] = i - w + 1;
                    }
                }
            }
            for &n in &neighbours {
                if n == usize::MAX || ids[n] != id {
                    continue;
                }
                let nl = prov[n];
                if label == u32::MAX {
                    label = nl;
                } else if nl != label {
                    union(&mut parent, label, nl);
                }
            }
            if label == u32::MAX {
                label = parent.len() as u32;
                parent.push(label);
            }
            prov[i] = label;
        }
    }
    // Resolve roots to final labels in raster order of first appearance.
    let mut final_of_root = vec![0u32; parent.len()];
    let mut components: Vec<Component> = Vec::new();
    let mut per_building: std::collections::HashMap<BuildingId, u32> = std::collections::HashMap::new();
    let mut labels = vec![0u32; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if prov[i] == u32::MAX {
                continue;
            }
            let root = find(&mut parent, prov[i]) as usize;
            if final_of_root[root] == 0 {
                let id = ids[i];
                let counter = per_building.entry(id).or_insert(0);
                components.push(Component {
                    building_id: id,
                    index: *counter,
                    area_px: 0,
                    bbox_px: [x as u32, y as u32, 0, 0],
                    touches_border: false,
                });
                *counter += 1;
                final_of_root[root] = components.len() as u32;
            }
            let l = final_of_root[root];
            labels[i] = l;
            let c = &mut components[l as usize - 1];
            c.area_px += 1;
            // bbox_px holds [min_x, min_y, max_x, max_y] until the end.
            c.bbox_px[0] = c.bbox_px[0].min(x as u32);
            c.bbox_px[2] = c.bbox_px[2].max(x as u32);
            c.bbox_px[3] = c.bbox_px[3].max(y as u32);
            if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
                c.touches_border = true;
            }
        }
    }
    for c in &mut components {
        let [x0, y0, x1, y1] = c.bbox_px;
        c.bbox_px = [x0, y0, x1 - x0 + 1, y1 - y0 + 1];
    }
    Labelling { width, height, labels, components }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(rows: &[&str]) -> IdMap {
        let h = rows.len() as u32;
        let w = rows[0].len() as u32;
        let ids = rows
            .iter()
            .flat_map(|r| r.bytes().map(|b| if b == b'.' { 0 } else { (b - b'0') as u32 }))
            .collect();
        IdMap::from_raw(w, h, ids).unwrap()
    }

    fn id(n: u32) -> BuildingId {
        BuildingId::new(n).unwrap()
    }

    #[test]
    fn diagonal_touch_depends_on_connectivity() {
        let map = grid(&["1..", ".1.", "..."]);
        assert_eq!(label_components(&map, Connectivity::Four).components.len(), 2);
        let l8 = label_components(&map, Connectivity::Eight);
        assert_eq!(l8.components.len(), 1);
        assert_eq!(l8.components[0].area_px, 2);
        assert_eq!(l8.components[0].bbox_px, [0, 0, 2, 2]);
    }

    #[test]
    fn same_building_split_by_another_gives_two_components() {
        let l = label_components(&grid(&["....", "1221", "1221", "...."]), Connectivity::Eight);
        let b1: Vec<_> = l.components.iter().filter(|c| c.building_id == id(1)).collect();
        assert_eq!(b1.len(), 2);
        assert_eq!((b1[0].index, b1[1].index), (0, 1));
        assert_eq!(b1[0].bbox_px, [0, 1, 1, 2]);
        assert_eq!(b1[1].bbox_px, [3, 1, 1, 2]);
        assert!(b1[0].touches_border && b1[1].touches_border);
        let b2 = l.components.iter().find(|c| c.building_id == id(2)).unwrap();
        assert_eq!((b2.area_px, b2.touches_border), (4, false));
    }

    #[test]
    fn u_shape_merges_late() {
        // The two arms meet only in the last row: union-find must merge them.
        let map = grid(&["1.1", "1.1", "111"]);
        let l = label_components(&map, Connectivity::Four);
        assert_eq!(l.components.len(), 1);
        assert_eq!(l.components[0].area_px, 7);
        assert!(l.labels.iter().zip(map.raw()).all(|(&lab, &id)| (lab == 0) == (id == 0)));
    }

    #[test]
    fn masks_partition_the_foreground() {
        let map = grid(&["11.22", "1..22", "..3..", "33.11"]);
        let ids = map.raw();
        let l = label_components(&map, Connectivity::Four);
        let mut cover = vec![0u8; ids.len()];
        for k in 0..l.components.len() {
            let m = l.mask(k);
            assert_eq!(m.iter().map(|&v| v as u64).sum::<u64>(), l.components[k].area_px);
            for (c, v) in cover.iter_mut().zip(m) {
                *c += v;
            }
        }
        assert!(cover.iter().zip(ids).all(|(&c, &id)| c == (id != 0) as u8));
    }
}
