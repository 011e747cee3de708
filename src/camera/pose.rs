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

use glam::{DMat3, DMat4, DQuat, DVec3};

/// A camera pose in the area's ENU frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Camera-to-world rotation: its columns are the camera axes in ENU.
    pub r_world_from_cam: DMat3,
    /// Camera centre in ENU metres relative to the area origin.
    pub centre_m: DVec3,
}

/// Rotation about the z axis by `a` radians (counter-clockwise seen from +z).
fn rot_z(a: f64) -> DMat3 {
    DMat3::from_rotation_z(a)
}

/// The nadir camera tilted by `pitch` radians towards north: columns x = (1, 0, 0),
/// y = (0, −cos p, −sin p), z = (0, sin p, −cos p) in ENU.
fn base(pitch: f64) -> DMat3 {
    let (s, c) = pitch.sin_cos();
    DMat3::from_cols(DVec3::X, DVec3::new(0.0, -c, -s), DVec3::new(0.0, s, -c))
}

impl Pose {
    /// Builds a pose from yaw/pitch/roll in degrees (see the module doc) and a centre in ENU metres.
    pub fn from_ypr_deg(yaw_deg: f64, pitch_deg: f64, roll_deg: f64, centre_m: impl Into<DVec3>) -> Self {
        let r = rot_z(-yaw_deg.to_radians()) * base(pitch_deg.to_radians()) * rot_z(roll_deg.to_radians());
        Pose { r_world_from_cam: r, centre_m: centre_m.into() }
    }

    /// Yaw, pitch, roll in degrees (inverse of [`Pose::from_ypr_deg`]); yaw in [0, 360). At exact nadir
    /// yaw and roll are the same rotation: roll is reported as 0 there.
    pub fn ypr_deg(&self) -> [f64; 3] {
        let r = &self.r_world_from_cam;
        let z = r.z_axis;
        let pitch = (-z.z).clamp(-1.0, 1.0).acos();
        let yaw = if pitch.sin() > 1e-9 {
            z.x.atan2(z.y)
        } else {
            // Nadir: heading from the camera x axis, (cos ψ, −sin ψ, 0) for roll 0.
            (-r.x_axis.y).atan2(r.x_axis.x)
        };
        let m = base(pitch).transpose() * (rot_z(yaw) * *r);
        let roll = m.x_axis.y.atan2(m.x_axis.x);
        let yaw_deg = yaw.to_degrees().rem_euclid(360.0);
        [if yaw_deg >= 360.0 { 0.0 } else { yaw_deg }, pitch.to_degrees(), roll.to_degrees()]
    }

    /// World-to-camera rotation Rᵀ.
    pub fn r_cam_from_world(&self) -> DMat3 {
        self.r_world_from_cam.transpose()
    }

    /// World-to-camera translation t = −Rᵀ C (COLMAP `tvec`).
    pub fn t_cam_from_world(&self) -> DVec3 {
        -(self.r_cam_from_world() * self.centre_m)
    }

    /// A world point (ENU metres) in camera coordinates.
    pub fn world_to_cam(&self, p_m: DVec3) -> DVec3 {
        self.r_cam_from_world() * (p_m - self.centre_m)
    }

    /// The camera-to-world transform (OpenCV camera axes, ENU metres).
    pub fn cam_to_world(&self) -> DMat4 {
        DMat4::from_mat3_translation(self.r_world_from_cam, self.centre_m)
    }

    /// The pose of a camera-to-world transform (its rotation part is taken as it is).
    pub fn from_cam_to_world(m: &DMat4) -> Pose {
        Pose { r_world_from_cam: DMat3::from_mat4(*m), centre_m: m.w_axis.truncate() }
    }

    /// The camera's viewing direction (its +z axis) in ENU.
    pub fn forward(&self) -> DVec3 {
        self.r_world_from_cam.z_axis
    }

    /// COLMAP world-to-camera quaternion (qw, qx, qy, qz), qw ≥ 0.
    pub fn colmap_qvec(&self) -> [f64; 4] {
        let q = quat_from_rotation(&self.r_cam_from_world());
        let q = if q.w < 0.0 { -q } else { q };
        [q.w, q.x, q.y, q.z]
    }

    /// Builds a pose from a COLMAP world-to-camera quaternion (qw, qx, qy, qz; normalised here) and
    /// translation.
    pub fn from_colmap(qvec: [f64; 4], tvec: [f64; 3]) -> Self {
        let [w, x, y, z] = qvec;
        let n = (w * w + x * x + y * y + z * z).sqrt();
        let r_cw = DMat3::from_quat(DQuat::from_xyzw(x / n, y / n, z / n, w / n));
        let r_wc = r_cw.transpose();
        Pose { r_world_from_cam: r_wc, centre_m: -(r_wc * DVec3::from(tvec)) }
    }

    /// Rotation angle between two poses' orientations in degrees:
    /// arccos((tr(R_aᵀ R_b) − 1) / 2), as in SPEC.md.
    pub fn rotation_error_deg(&self, other: &Pose) -> f64 {
        let m = self.r_world_from_cam.transpose() * other.r_world_from_cam;
        let tr = m.x_axis.x + m.y_axis.y + m.z_axis.z;
        ((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Distance between camera centres in metres.
    pub fn translation_error_m(&self, other: &Pose) -> f64 {
        self.centre_m.distance(other.centre_m)
    }

    /// `other`'s centre relative to this pose split along this camera's viewing direction (signed:
    /// positive is in front, i.e. closer to what the camera sees) and across it, in metres. A narrow
    /// field of view observes the first far less than the second: moving along the axis by d at a
    /// range R changes the image scale by only d/R.
    pub fn axial_lateral_error_m(&self, other: &Pose) -> (f64, f64) {
        let d = other.centre_m - self.centre_m;
        let axial = d.dot(self.forward());
        (axial, (d - axial * self.forward()).length())
    }
}

/// The unit quaternion of a rotation matrix by Shepperd's method (the branch on the largest diagonal
/// term). glam's `DQuat::from_mat3` branches differently and so differs in the last bits; this one is
/// kept so that the COLMAP quaternions written to `poses.jsonl` do not change between versions.
fn quat_from_rotation(m: &DMat3) -> DQuat {
    let e = |r: usize, c: usize| m.col(c)[r];
    let tr = e(0, 0) + e(1, 1) + e(2, 2);
    // (w, x, y, z)
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [0.25 * s, (e(2, 1) - e(1, 2)) / s, (e(0, 2) - e(2, 0)) / s, (e(1, 0) - e(0, 1)) / s]
    } else if e(0, 0) > e(1, 1) && e(0, 0) > e(2, 2) {
        let s = (1.0 + e(0, 0) - e(1, 1) - e(2, 2)).sqrt() * 2.0;
        [(e(2, 1) - e(1, 2)) / s, 0.25 * s, (e(0, 1) + e(1, 0)) / s, (e(0, 2) + e(2, 0)) / s]
    } else if e(1, 1) > e(2, 2) {
        let s = (1.0 + e(1, 1) - e(0, 0) - e(2, 2)).sqrt() * 2.0;
        [(e(0, 2) - e(2, 0)) / s, (e(0, 1) + e(1, 0)) / s, 0.25 * s, (e(1, 2) + e(2, 1)) / s]
    } else {
        let s = (1.0 + e(2, 2) - e(0, 0) - e(1, 1)).sqrt() * 2.0;
        [(e(1, 0) - e(0, 1)) / s, (e(0, 2) + e(2, 0)) / s, (e(1, 2) + e(2, 1)) / s, 0.25 * s]
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    DQuat::from_xyzw(q[1] / n, q[2] / n, q[3] / n, q[0] / n)
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
        let cols = p.r_world_from_cam.to_cols_array_2d();
        assert_eq!(
            cols,
            [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]].map(|c| c.map(|v: f64| v + 0.0))
        );
        // A point 10 m north of the nadir point projects above the image centre (negative y).
        let c = p.world_to_cam(DVec3::new(0.0, 10.0, 0.0));
        assert!(close(c[0], 0.0, 1e-12) && close(c[1], -10.0, 1e-12) && close(c[2], 100.0, 1e-12));
    }

    #[test]
    fn tilted_east_looks_east() {
        let p = Pose::from_ypr_deg(90.0, 90.0, 0.0, [0.0, 0.0, 0.0]);
        let c = p.world_to_cam(DVec3::new(50.0, 0.0, 0.0));
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
        let back = Pose::from_colmap(pose.colmap_qvec(), pose.t_cam_from_world().to_array());
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
