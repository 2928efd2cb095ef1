//! The camera's calibration and its 20 Hz RGB-D frame.

use crate::message::{HEADER_BYTES as H, Header, Message, message};
use crate::topics;
use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;

/// Largest camera image width carried by [`CameraFrame`], pixels.
pub const MAX_IMAGE_WIDTH: usize = 256;
/// Largest camera image height carried by [`CameraFrame`], pixels.
pub const MAX_IMAGE_HEIGHT: usize = 256;

/// A calibrated pinhole camera (square pixels, no distortion): the one
/// calibration type of the stack, carried in every [`CameraFrame`], logged
/// with it, and what the flow labeler and the simulator's camera are built
/// from.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    ZeroCopySend,
    Pod,
    Zeroable,
    serde::Serialize,
    serde::Deserialize,
)]
pub struct CameraCalibration {
    /// Image width, pixels (≤ [`MAX_IMAGE_WIDTH`] in a message).
    pub width: u32,
    /// Image height, pixels (≤ [`MAX_IMAGE_HEIGHT`] in a message).
    pub height: u32,
    /// Focal length, pixels.
    pub focal_px: f64,
    /// Principal point (x, y), pixels.
    pub principal_px: [f64; 2],
    /// Camera position in the base frame, m. Camera axes: x right, y down,
    /// z forward (optical).
    pub pose_pos_m: [f64; 3],
    /// Camera orientation in the base frame, quaternion (x, y, z, w).
    pub pose_quat_xyzw: [f64; 4],
}

impl std::fmt::Display for CameraCalibration {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.pose_pos_m;
        let [qx, qy, qz, qw] = self.pose_quat_xyzw;
        write!(
            f,
            "{}×{} px, focal {:.2} px, at ({x:.4}, {y:.4}, {z:.4}) m, \
             quaternion ({qx:.4}, {qy:.4}, {qz:.4}, {qw:.4})",
            self.width, self.height, self.focal_px
        )
    }
}

impl CameraCalibration {
    /// Whether `other` is the same camera: the same image size, focal
    /// length and principal point within 10⁻³ px, position within 0.1 mm and
    /// orientation within about 10⁻³ rad (`q` and `−q` are one rotation).
    /// The tolerances absorb a calibration's round trip through f32 or text,
    /// not a moved camera: a learned encoder sees a camera moved by a few
    /// millimetres as a different scene.
    pub fn same_camera(&self, other: &Self) -> bool {
        let near =
            |a: &[f64], b: &[f64], tol: f64| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol);
        let dot = |a: &[f64; 4], b: &[f64; 4]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (qa, qb) = (&self.pose_quat_xyzw, &other.pose_quat_xyzw);
        let norms = (dot(qa, qa) * dot(qb, qb)).sqrt();
        // |q̂a·q̂b| = cos(θ/2) for a rotation θ between them: θ ≤ 10⁻³ rad.
        // A zero (or non-finite) quaternion is no orientation: no match.
        norms > 1e-12
            && norms.is_finite()
            && (dot(qa, qb) / norms).abs() >= (0.5e-3f64).cos()
            && self.width == other.width
            && self.height == other.height
            && (self.focal_px - other.focal_px).abs() <= 1e-3
            && near(&self.principal_px, &other.principal_px, 1e-3)
            && near(&self.pose_pos_m, &other.pose_pos_m, 1e-4)
    }
}

/// Robot (camera driver) → learner, 20 Hz: an RGB-D image with its
/// calibration. Only the first `width × height` pixels of each buffer are
/// meaningful.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Pod, Zeroable)]
pub struct CameraFrame {
    /// Header (`t_hw_ns`: exposure time).
    pub header: Header,
    /// Frame counter since start.
    pub index: u64,
    /// The image size and the camera's intrinsics and pose.
    pub calibration: CameraCalibration,
    /// RGB, row-major, 3 bytes per pixel.
    pub rgb: [u8; MAX_IMAGE_WIDTH * MAX_IMAGE_HEIGHT * 3],
    /// Depth along the optical axis, m, row-major (0: no return).
    pub depth_m: [f32; MAX_IMAGE_WIDTH * MAX_IMAGE_HEIGHT],
}

message!(CameraFrame, topics::CAMERA, "CameraFrame");

// Layouts (`Pod` rejects padding; these pin the sizes).
const _: () = assert!(
    size_of::<CameraFrame>()
        == H + 8 + 8 + 8 + 16 + 24 + 32 + MAX_IMAGE_WIDTH * MAX_IMAGE_HEIGHT * 7
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_camera_within_round_trip_not_moved() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let a = CameraCalibration {
            width: 128,
            height: 128,
            focal_px: 175.8,
            principal_px: [64.0, 64.0],
            pose_pos_m: [0.9, -0.24, 0.77],
            pose_quat_xyzw: [h, 0.0, 0.0, h],
        };
        assert!(a.same_camera(&a));
        // The same rotation written as -q, and an f32 round trip.
        let mut b = a;
        b.pose_quat_xyzw = a.pose_quat_xyzw.map(|x| -x);
        b.pose_pos_m = a.pose_pos_m.map(|x| x as f32 as f64);
        b.focal_px = a.focal_px as f32 as f64;
        assert!(a.same_camera(&b));
        let moved = |f: &dyn Fn(&mut CameraCalibration)| {
            let mut c = a;
            f(&mut c);
            !a.same_camera(&c) && !c.same_camera(&a)
        };
        assert!(moved(&|c| c.width = 64));
        assert!(moved(&|c| c.height = 96));
        assert!(moved(&|c| c.focal_px += 0.5));
        assert!(moved(&|c| c.principal_px[1] += 0.5));
        assert!(moved(&|c| c.pose_pos_m[2] += 0.001));
        // Turned about z by θ: the same within 10⁻³ rad, not beyond; a
        // quaternion of another norm is the same rotation.
        let turned = |theta: f64, scale: f64| {
            let (s, k) = ((theta / 2.0).sin(), (theta / 2.0).cos());
            let mut c = a;
            c.pose_quat_xyzw = [h * k, h * s, h * s, h * k].map(|x| x * scale);
            c
        };
        assert!(a.same_camera(&turned(0.8e-3, 1.0)));
        assert!(a.same_camera(&turned(0.0, 2.0)));
        assert!(!a.same_camera(&turned(1.5e-3, 1.0)));
        assert!(!a.same_camera(&turned(0.01, 1.0)));
        // Just inside and outside the other tolerances.
        let same = |f: &dyn Fn(&mut CameraCalibration)| {
            let mut c = a;
            f(&mut c);
            a.same_camera(&c) && c.same_camera(&a)
        };
        assert!(same(&|c| c.pose_pos_m[0] += 0.8e-4));
        assert!(moved(&|c| c.pose_pos_m[0] += 2e-4));
        assert!(same(&|c| c.focal_px += 0.8e-3));
        assert!(moved(&|c| c.focal_px += 2e-3));
        // No orientation matches nothing, itself included.
        assert!(!CameraCalibration::default().same_camera(&CameraCalibration::default()));
    }
}
