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
}
