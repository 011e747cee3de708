//! Camera poses in the area's ENU frame and their representations.
//!
//! A [`Pose`] stores the camera-to-world rotation (columns = camera axes in ENU, OpenCV camera axes:
//! x right, y down, z forward) and the camera centre in ENU metres relative to the area origin, all f64.
//!
//! Angle convention ([`Pose::from_ypr_deg`]), chosen for UAV imagery:
//! - `yaw_deg`: heading of the top of the image, clockwise from north (0 = north, 90 = east);
//! - `pitch_deg`: tilt of the optical axis from nadir (0 = looking straight down, 90 = horizontal),
//!   the camera tilting towards its heading — the paper's "view angle";
//! - `roll_deg`: rotation about the optical axis, positive turning the image clockwise as seen by the
//!   camera.
//!
//! R_world_from_cam = Rz(−yaw) · B(pitch) · Rz(roll), where B(pitch) has columns x = (1, 0, 0),
//! y = (0, −cos p, −sin p), z = (0, sin p, −cos p) in ENU.

use serde::{Deserialize, Serialize};

pub type Mat3 = [[f64; 3]; 3];

/// A camera pose in the area's ENU frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Camera-to-world rotation, row-major; its columns are the camera axes in ENU.
    pub r_world_from_cam: Mat3,
    /// Camera centre in ENU metres relative to the area origin.
    pub centre_m: [f64; 3],
}

pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    c
}

pub fn transpose(a: &Mat3) -> Mat3 {
    let mut t = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            t[i][j] = a[j][i];
        }
    }
    t
}

pub fn mat_vec(a: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [
        a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
        a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
        a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2],
    ]
}

/// a − b.
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// The cross product a × b.
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The dot product a · b.
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Rotation about the z axis by `a` radians (counter-clockwise seen from +z).
fn rot_z(a: f64) -> Mat3 {
    let (s, c) = a.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}

fn base(pitch: f64) -> Mat3 {
    let (s, c) = pitch.sin_cos();
    [[1.0, 0.0, 0.0], [0.0, -c, s], [0.0, -s, -c]]
}

impl Pose {
    /// Builds a pose from yaw/pitch/roll in degrees (see the module doc) and a centre in ENU metres.
    pub fn from_ypr_deg(yaw_deg: f64, pitch_deg: f64, roll_deg: f64, centre_m: [f64; 3]) -> Self {
        let r = mat_mul(
            &mat_mul(&rot_z(-yaw_deg.to_radians()), &base(pitch_deg.to_radians())),
            &rot_z(roll_deg.to_radians()),
        );
        Pose { r_world_from_cam: r, centre_m }
    }

    /// Yaw, pitch, roll in degrees (inverse of [`Pose::from_ypr_deg`]); yaw in [0, 360). At exact nadir
    /// yaw and roll are the same rotation: roll is reported as 0 there.
    pub fn ypr_deg(&self) -> [f64; 3] {
        let r = &self.r_world_from_cam;
        let z = [r[0][2], r[1][2], r[2][2]];
        let pitch = (-z[2]).clamp(-1.0, 1.0).acos();
        let yaw = if pitch.sin() > 1e-9 {
            z[0].atan2(z[1])
        } else {
            // Nadir: heading from the camera x axis, (cos ψ, −sin ψ, 0) for roll 0.
            (-r[1][0]).atan2(r[0][0])
        };
        let m = mat_mul(&transpose(&base(pitch)), &mat_mul(&rot_z(yaw), r));
        let roll = m[1][0].atan2(m[0][0]);
        let yaw_deg = yaw.to_degrees().rem_euclid(360.0);
        [if yaw_deg >= 360.0 { 0.0 } else { yaw_deg }, pitch.to_degrees(), roll.to_degrees()]
    }

    /// World-to-camera rotation Rᵀ.
    pub fn r_cam_from_world(&self) -> Mat3 {
        transpose(&self.r_world_from_cam)
    }

    /// World-to-camera translation t = −Rᵀ C (COLMAP `tvec`).
    pub fn t_cam_from_world(&self) -> [f64; 3] {
        let rt = self.r_cam_from_world();
        let t = mat_vec(&rt, self.centre_m);
        [-t[0], -t[1], -t[2]]
    }

    /// A world point (ENU metres) in camera coordinates.
    pub fn world_to_cam(&self, p_m: [f64; 3]) -> [f64; 3] {
        let d = [p_m[0] - self.centre_m[0], p_m[1] - self.centre_m[1], p_m[2] - self.centre_m[2]];
        mat_vec(&self.r_cam_from_world(), d)
    }

    /// COLMAP world-to-camera quaternion (qw, qx, qy, qz), qw ≥ 0.
    pub fn colmap_qvec(&self) -> [f64; 4] {
        let q = quat_from_mat(&self.r_cam_from_world());
        if q[0] < 0.0 {
            [-q[0], -q[1], -q[2], -q[3]]
        } else {
            q
        }
    }

    /// Builds a pose from a COLMAP world-to-camera quaternion and translation.
    pub fn from_colmap(qvec: [f64; 4], tvec: [f64; 3]) -> Self {
        let r_cw = mat_from_quat(qvec);
        let r_wc = transpose(&r_cw);
        let c = mat_vec(&r_wc, tvec);
        Pose { r_world_from_cam: r_wc, centre_m: [-c[0], -c[1], -c[2]] }
    }

    /// Rotation angle between two poses' orientations in degrees:
    /// arccos((tr(R_aᵀ R_b) − 1) / 2), as in SPEC.md.
    pub fn rotation_error_deg(&self, other: &Pose) -> f64 {
        let m = mat_mul(&transpose(&self.r_world_from_cam), &other.r_world_from_cam);
        let tr = m[0][0] + m[1][1] + m[2][2];
        ((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Distance between camera centres in metres.
    pub fn translation_error_m(&self, other: &Pose) -> f64 {
        let d = [
            self.centre_m[0] - other.centre_m[0],
            self.centre_m[1] - other.centre_m[1],
            self.centre_m[2] - other.centre_m[2],
        ];
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    }
}

/// Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method).
pub fn quat_from_mat(m: &Mat3) -> [f64; 4] {
    let tr = m[0][0] + m[1][1] + m[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [0.25 * s, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [(m[2][1] - m[1][2]) / s, 0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [(m[0][2] - m[2][0]) / s, (m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [(m[1][0] - m[0][1]) / s, (m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s]
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    [q[0] / n, q[1] / n, q[2] / n, q[3] / n]
}

/// Rotation matrix of a quaternion (w, x, y, z); the quaternion is normalised first.
pub fn mat_from_quat(q: [f64; 4]) -> Mat3 {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, eps: f64) -> bool {
        (a - b).abs() <= eps
    }

    #[test]
    fn nadir_north_up_axes() {
        let p = Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]);
        // x right = east, y down = south, z forward = down.
        let r = p.r_world_from_cam;
        let cols = [[r[0][0], r[1][0], r[2][0]], [r[0][1], r[1][1], r[2][1]], [r[0][2], r[1][2], r[2][2]]];
        assert_eq!(
            cols,
            [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]].map(|c| c.map(|v: f64| v + 0.0))
        );
        // A point 10 m north of the nadir point projects above the image centre (negative y).
        let c = p.world_to_cam([0.0, 10.0, 0.0]);
        assert!(close(c[0], 0.0, 1e-12) && close(c[1], -10.0, 1e-12) && close(c[2], 100.0, 1e-12));
    }

    #[test]
    fn tilted_east_looks_east() {
        let p = Pose::from_ypr_deg(90.0, 90.0, 0.0, [0.0, 0.0, 0.0]);
        let c = p.world_to_cam([50.0, 0.0, 0.0]);
        assert!(close(c[2], 50.0, 1e-9) && close(c[0], 0.0, 1e-9) && close(c[1], 0.0, 1e-9), "{c:?}");
    }

    #[test]
    fn ypr_round_trip() {
        for &(y, p, r) in
            &[(0.0, 0.0, 0.0), (33.0, 45.0, 0.0), (271.5, 12.0, -3.0), (359.0, 70.0, 5.0), (120.0, 0.0, 0.0)]
        {
            let pose = Pose::from_ypr_deg(y, p, r, [1.0, 2.0, 3.0]);
            let [y2, p2, r2] = pose.ypr_deg();
            assert!(
                close(y, y2, 1e-9) && close(p, p2, 1e-9) && close(r, r2, 1e-9),
                "{y} {p} {r} → {y2} {p2} {r2}"
            );
        }
    }

    #[test]
    fn colmap_round_trip() {
        let pose = Pose::from_ypr_deg(212.0, 38.0, 1.5, [123.4, -56.7, 345.6]);
        let back = Pose::from_colmap(pose.colmap_qvec(), pose.t_cam_from_world());
        assert!(pose.translation_error_m(&back) < 1e-9);
        assert!(pose.rotation_error_deg(&back) < 1e-6);
    }

    #[test]
    fn rotation_error_of_pure_yaw() {
        let a = Pose::from_ypr_deg(10.0, 0.0, 0.0, [0.0; 3]);
        let b = Pose::from_ypr_deg(13.0, 0.0, 0.0, [0.0; 3]);
        assert!(close(a.rotation_error_deg(&b), 3.0, 1e-9));
    }
}
