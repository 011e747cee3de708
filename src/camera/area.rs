//! The area polygon in ENU metres, with the few planar queries the samplers need: containment,
//! distance to the boundary, line clipping, random interior points and the principal axis.

use rand::Rng;

use super::{AreaProblem, CameraError};

/// A simple polygon (open ring, either orientation) in ENU metres (east, north).
#[derive(Debug, Clone, PartialEq)]
pub struct AreaPolygon {
    ring: Vec<[f64; 2]>,
    /// Bounds [min_e, min_n], [max_e, max_n].
    pub min_m: [f64; 2],
    /// Bounds' maximum corner [max_e, max_n], metres.
    pub max_m: [f64; 2],
}

impl AreaPolygon {
    /// Validates and wraps `ring` (a closing vertex equal to the first is dropped).
    ///
    /// # Errors
    /// [`CameraError::Area`] for fewer than 3 distinct vertices, non-finite coordinates or zero area.
    pub fn new(area: &str, ring: &[[f64; 2]]) -> Result<Self, CameraError> {
        let fail = |problem| CameraError::Area { area: area.to_string(), problem };
        let mut pts: Vec<[f64; 2]> = ring.to_vec();
        if pts.len() > 1 && pts.first() == pts.last() {
            pts.pop();
        }
        if let Some(p) = pts.iter().find(|p| !(p[0].is_finite() && p[1].is_finite())) {
            return Err(fail(AreaProblem::NonFiniteVertex { vertex: *p }));
        }
        if pts.len() < 3 {
            return Err(fail(AreaProblem::TooFewVertices { vertices: pts.len() }));
        }
        let mut min_m = [f64::INFINITY; 2];
        let mut max_m = [f64::NEG_INFINITY; 2];
        for p in &pts {
            for k in 0..2 {
                min_m[k] = min_m[k].min(p[k]);
                max_m[k] = max_m[k].max(p[k]);
            }
        }
        let poly = AreaPolygon { ring: pts, min_m, max_m };
        if poly.area_m2() < 1.0 {
            return Err(fail(AreaProblem::Empty { area_m2: poly.area_m2() }));
        }
        Ok(poly)
    }

    /// The vertices (open ring).
    pub fn ring(&self) -> &[[f64; 2]] {
        &self.ring
    }

    /// Enclosed area, m² (absolute value of the shoelace sum).
    pub fn area_m2(&self) -> f64 {
        let n = self.ring.len();
        let mut s = 0.0;
        for i in 0..n {
            let (a, b) = (self.ring[i], self.ring[(i + 1) % n]);
            s += a[0] * b[1] - b[0] * a[1];
        }
        0.5 * s.abs()
    }

    fn edges(&self) -> impl Iterator<Item = ([f64; 2], [f64; 2])> + '_ {
        let n = self.ring.len();
        (0..n).map(move |i| (self.ring[i], self.ring[(i + 1) % n]))
    }

    /// Whether `p` lies inside (even–odd rule; points exactly on an edge may go either way).
    pub fn contains(&self, p: [f64; 2]) -> bool {
        crate::util::point_in_polygon(p, &self.ring)
    }

    /// Distance from `p` to the nearest edge, metres.
    pub fn distance_to_boundary_m(&self, p: [f64; 2]) -> f64 {
        self.edges().map(|(a, b)| point_segment_distance(p, a, b)).fold(f64::INFINITY, f64::min)
    }

    /// Whether `p` is inside and at least `margin_m` from the boundary.
    pub fn contains_with_margin(&self, p: [f64; 2], margin_m: f64) -> bool {
        self.contains(p) && (margin_m <= 0.0 || self.distance_to_boundary_m(p) >= margin_m)
    }

    /// The parameter intervals [s0, s1] (s0 < s1) where the line `origin + s · dir` is inside the
    /// polygon, in increasing order; `dir` should be a unit vector so that s is in metres.
    pub fn clip_line(&self, origin: [f64; 2], dir: [f64; 2]) -> Vec<[f64; 2]> {
        let mut ss = Vec::new();
        for (a, b) in self.edges() {
            // Solve origin + s·dir = a + u·(b − a), u in [0, 1).
            let e = [b[0] - a[0], b[1] - a[1]];
            let den = dir[0] * e[1] - dir[1] * e[0];
            if den.abs() < 1e-12 {
                continue;
            }
            let w = [a[0] - origin[0], a[1] - origin[1]];
            let s = (w[0] * e[1] - w[1] * e[0]) / den;
            // An edge crosses the line when its ends lie on different sides; the half-open side test
            // counts a crossing through a vertex exactly once.
            let (ya, yb) = (side(a, origin, dir), side(b, origin, dir));
            if (ya > 0.0) != (yb > 0.0) {
                ss.push(s);
            }
        }
        ss.sort_by(f64::total_cmp);
        ss.chunks_exact(2).filter(|c| c[1] > c[0]).map(|c| [c[0], c[1]]).collect()
    }

    /// A uniformly random point inside the polygon at least `margin_m` from its boundary, by
    /// rejection sampling in the bounding box; halves the margin after every 200 failures and
    /// returns `None` only if even margin 0 fails 200 times (a sliver polygon).
    pub fn random_point<R: Rng>(&self, rng: &mut R, margin_m: f64) -> Option<[f64; 2]> {
        let mut margin = margin_m;
        loop {
            for _ in 0..200 {
                let p = [
                    rng.gen_range(self.min_m[0]..=self.max_m[0]),
                    rng.gen_range(self.min_m[1]..=self.max_m[1]),
                ];
                if self.contains_with_margin(p, margin) {
                    return Some(p);
                }
            }
            if margin <= 0.0 {
                return None;
            }
            margin = if margin < 1.0 { 0.0 } else { margin * 0.5 };
        }
    }

    /// Heading (degrees clockwise from north, in [0, 180)) of the principal axis of the polygon's
    /// area distribution (second moments of the filled polygon), i.e. the direction along which the
    /// area is longest.
    pub fn principal_axis_heading_deg(&self) -> f64 {
        // Area moments by the shoelace decomposition into triangles with the first vertex.
        let o = self.ring[0];
        let (mut a_sum, mut cx, mut cy) = (0.0, 0.0, 0.0);
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for (a, b) in self.edges() {
            let (x0, y0) = (a[0] - o[0], a[1] - o[1]);
            let (x1, y1) = (b[0] - o[0], b[1] - o[1]);
            let cross = x0 * y1 - x1 * y0;
            a_sum += cross / 2.0;
            cx += (x0 + x1) * cross / 6.0;
            cy += (y0 + y1) * cross / 6.0;
            sxx += (x0 * x0 + x0 * x1 + x1 * x1) * cross / 12.0;
            syy += (y0 * y0 + y0 * y1 + y1 * y1) * cross / 12.0;
            sxy += (x0 * y1 + 2.0 * x0 * y0 + 2.0 * x1 * y1 + x1 * y0) * cross / 24.0;
        }
        let (mx, my) = (cx / a_sum, cy / a_sum);
        let cxx = sxx / a_sum - mx * mx;
        let cyy = syy / a_sum - my * my;
        let cxy = sxy / a_sum - mx * my;
        // Angle of the major axis from east, counter-clockwise.
        let theta = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
        (90.0 - theta.to_degrees()).rem_euclid(180.0)
    }
}

fn side(p: [f64; 2], origin: [f64; 2], dir: [f64; 2]) -> f64 {
    (p[0] - origin[0]) * dir[1] - (p[1] - origin[1]) * dir[0]
}

fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = [b[0] - a[0], b[1] - a[1]];
    let ap = [p[0] - a[0], p[1] - a[1]];
    let l2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if l2 > 0.0 { ((ap[0] * ab[0] + ap[1] * ab[1]) / l2).clamp(0.0, 1.0) } else { 0.0 };
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1]];
    (d[0] * d[0] + d[1] * d[1]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn l_shape() -> AreaPolygon {
        // An L: 200 × 100 bar plus a 100 × 100 block on its left end (area 30 000 m²).
        AreaPolygon::new(
            "t",
            &[[0.0, 0.0], [200.0, 0.0], [200.0, 100.0], [100.0, 100.0], [100.0, 200.0], [0.0, 200.0]],
        )
        .unwrap()
    }

    #[test]
    fn area_containment_distance() {
        let p = l_shape();
        assert_eq!(p.area_m2(), 30_000.0);
        assert!(p.contains([50.0, 150.0]) && !p.contains([150.0, 150.0]) && !p.contains([-1.0, 5.0]));
        assert_eq!(p.distance_to_boundary_m([50.0, 150.0]), 50.0);
        assert!((p.distance_to_boundary_m([150.0, 150.0]) - 50.0).abs() < 1e-12);
    }

    #[test]
    fn clipping_a_line_through_a_concave_polygon() {
        let p = l_shape();
        // The horizontal line y = 150 enters at x = 0 and leaves at x = 100.
        assert_eq!(p.clip_line([-10.0, 150.0], [1.0, 0.0]), vec![[10.0, 110.0]]);
        // The vertical line x = 150 is inside for y in [0, 100].
        assert_eq!(p.clip_line([150.0, -50.0], [0.0, 1.0]), vec![[50.0, 150.0]]);
    }

    #[test]
    fn degenerate_polygons_are_errors() {
        let e = AreaPolygon::new("a", &[[0.0, 0.0], [1.0, 1.0]]).unwrap_err().to_string();
        assert!(e.contains("area a") && e.contains("2 vertices"), "{e}");
        let e = AreaPolygon::new("a", &[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]).unwrap_err().to_string();
        assert!(e.contains("is empty"), "{e}");
    }

    #[test]
    fn principal_axis_of_rectangles() {
        let ew = AreaPolygon::new("t", &[[0.0, 0.0], [400.0, 0.0], [400.0, 100.0], [0.0, 100.0]]).unwrap();
        assert!((ew.principal_axis_heading_deg() - 90.0).abs() < 1e-9);
        let ns = AreaPolygon::new("t", &[[0.0, 0.0], [100.0, 0.0], [100.0, 400.0], [0.0, 400.0]]).unwrap();
        let h = ns.principal_axis_heading_deg();
        assert!(h.min(180.0 - h) < 1e-9, "{h}");
    }
}
