//! Small numeric and planar helpers that several stages share.

/// The median of `values` (the mean of the two middle values for an even count), or `None` when there
/// are none. NaNs sort after every number (`f64::total_cmp`).
pub fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

/// Whether `p` lies inside the polygon `ring` (an open ring in either orientation), by the even–odd
/// rule; points exactly on an edge may go either way. An empty ring contains nothing.
///
/// # Units
/// Any planar coordinates, the same for `p` and `ring` (ENU metres in insgen).
pub fn point_in_polygon(p: [f64; 2], ring: &[[f64; 2]]) -> bool {
    let n = ring.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// The convex hull of `points` (Andrew's monotone chain): its vertices counter-clockwise from the
/// leftmost-then-lowest one, without collinear vertices or repeats. Fewer than three distinct points,
/// or all on a line, give those extreme points (0–2 of them): a hull without area. Non-finite points
/// are ignored.
///
/// # Units
/// Any planar coordinates (ENU metres in insgen).
pub fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> =
        points.iter().copied().filter(|q| q[0].is_finite() && q[1].is_finite()).collect();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross =
        |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    // The lower chain left to right, then the upper chain back: counter-clockwise.
    for pass in [p.clone(), p.iter().rev().copied().collect()] {
        let start = hull.len();
        for q in pass {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_even_and_empty_lists() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(&[7.0]), Some(7.0));
        assert_eq!(median(&[]), None);
    }

    #[test]
    fn point_in_square_and_concave_polygon() {
        let sq = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert!(point_in_polygon([0.5, 0.5], &sq));
        assert!(!point_in_polygon([1.5, 0.5], &sq));
        // Clockwise gives the same answer.
        let cw: Vec<[f64; 2]> = sq.iter().rev().copied().collect();
        assert!(point_in_polygon([0.5, 0.5], &cw));
        // An L: the notch (1.5, 1.5) is outside.
        let l = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]];
        assert!(point_in_polygon([0.5, 1.5], &l) && point_in_polygon([1.5, 0.5], &l));
        assert!(!point_in_polygon([1.5, 1.5], &l));
        assert!(!point_in_polygon([0.0, 0.0], &[]));
    }

    #[test]
    fn convex_hull_of_a_square_with_inner_and_edge_points() {
        let pts =
            [[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [2.0, 2.0], [0.0, 2.0], [1.0, 1.0], [0.5, 1.5], [2.0, 2.0]];
        let hull = convex_hull(&pts);
        assert_eq!(hull, vec![[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]);
        // Counter-clockwise: positive shoelace area.
        let twice_area: f64 = (0..hull.len())
            .map(|i| {
                let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum();
        assert_eq!(twice_area, 8.0);
        assert!(point_in_polygon([1.9, 0.1], &hull) && !point_in_polygon([2.1, 1.0], &hull));
    }

    #[test]
    fn convex_hull_without_area() {
        assert!(convex_hull(&[]).is_empty());
        assert_eq!(convex_hull(&[[1.0, 1.0], [1.0, 1.0]]), vec![[1.0, 1.0]]);
        assert_eq!(convex_hull(&[[0.0, 0.0], [f64::NAN, 1.0], [3.0, 3.0]]), vec![[0.0, 0.0], [3.0, 3.0]]);
        // Collinear points: the two ends.
        let line = convex_hull(&[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]);
        assert_eq!(line, vec![[0.0, 0.0], [3.0, 3.0]]);
    }
}
