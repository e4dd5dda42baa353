//! The pinhole with Brown-Conrady radial distortion, and the mounting that puts it on
//! the body.
//!
//! Camera axes: `+z` the boresight, `+x` towards increasing column, `+y` towards
//! increasing row (`z x x`). A direction `(X, Y, Z)` with `Z > 0` has normalised
//! coordinates `x = X/Z, y = Y/Z`, distorted radially (Brown 1966; Conrady 1919):
//!
//! ```text
//! r^2 = x^2 + y^2,  d = 1 + k1 r^2 + k2 r^4,  u = cx + f x d,  v = cy + f y d
//! f = (W / 2) / tan(fov / 2),  cx = W / 2,  cy = H / 2   (pixels)
//! ```
//!
//! Pixel `(i, j)` (column, row) covers `u in [i, i+1)`, `v in [j, j+1)`; its centre is
//! `(i + 0.5, j + 0.5)`. Row 0 is the top row.

use nalgebra::{Matrix3, Vector3};

/// Intrinsics of a pinhole camera with radial distortion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Focal length, pixels.
    pub f_px: f64,
    /// Principal point, pixels.
    pub cx: f64,
    /// Principal point, pixels.
    pub cy: f64,
    /// Radial distortion coefficients.
    pub k1: f64,
    /// Radial distortion coefficients.
    pub k2: f64,
}

impl Pinhole {
    /// A camera `width x height` with `fov_deg` across the width.
    pub fn new(width: u32, height: u32, fov_deg: f64, k1: f64, k2: f64) -> Self {
        let f_px = 0.5 * width as f64 / (0.5 * fov_deg.to_radians()).tan();
        Self {
            width,
            height,
            f_px,
            cx: 0.5 * width as f64,
            cy: 0.5 * height as f64,
            k1,
            k2,
        }
    }

    /// The distortion factor `d(r^2)`.
    #[inline]
    fn factor(&self, r2: f64) -> f64 {
        1.0 + r2 * (self.k1 + self.k2 * r2)
    }

    /// Image point `(u, v)` of a camera-frame direction; `None` behind the camera
    /// (`Z <= 0`) or where the distortion polynomial folds back (`d(r^2) r` no longer
    /// increasing: a wide-angle point the model cannot image).
    #[inline]
    pub fn project(&self, p_cam: &Vector3<f64>) -> Option<(f64, f64)> {
        if p_cam.z <= 0.0 {
            return None;
        }
        let x = p_cam.x / p_cam.z;
        let y = p_cam.y / p_cam.z;
        let r2 = x * x + y * y;
        // d(r d)/dr = 1 + 3 k1 r^2 + 5 k2 r^4 must stay positive.
        if 1.0 + r2 * (3.0 * self.k1 + 5.0 * self.k2 * r2) <= 0.0 {
            return None;
        }
        let d = self.factor(r2);
        Some((self.cx + self.f_px * x * d, self.cy + self.f_px * y * d))
    }

    /// Unit camera-frame direction of image point `(u, v)`: the inverse of
    /// [`Self::project`], by Newton's method on the radial polynomial (converges to
    /// 1e-15 in a few steps for the distortions the configuration allows in the field).
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        let xd = (u - self.cx) / self.f_px;
        let yd = (v - self.cy) / self.f_px;
        let rd = xd.hypot(yd);
        let mut r = rd;
        for _ in 0..20 {
            let r2 = r * r;
            let g = r * self.factor(r2) - rd;
            let dg = 1.0 + r2 * (3.0 * self.k1 + 5.0 * self.k2 * r2);
            if dg <= 0.0 {
                break;
            }
            let step = g / dg;
            r -= step;
            if step.abs() < 1e-15 * (1.0 + r) {
                break;
            }
        }
        let s = if rd > 0.0 { r / rd } else { 1.0 };
        Vector3::new(xd * s, yd * s, 1.0).normalize()
    }

    /// Unit direction through the centre of pixel `(i, j)`.
    #[inline]
    pub fn pixel_ray(&self, i: u32, j: u32) -> Vector3<f64> {
        self.ray(i as f64 + 0.5, j as f64 + 0.5)
    }

    /// Angle subtended by one pixel at the principal point, rad.
    pub fn pixel_angle_rad(&self) -> f64 {
        1.0 / self.f_px
    }
}

/// The rotation taking camera-frame directions into body axes, from a boresight and an
/// image-right direction (made perpendicular to the boresight).
pub fn body_from_camera(boresight_body: [f64; 3], right_body: [f64; 3]) -> Matrix3<f64> {
    let z = Vector3::from(boresight_body).normalize();
    let r = Vector3::from(right_body);
    let x = (r - z * z.dot(&r)).normalize();
    let y = z.cross(&x);
    Matrix3::from_columns(&[x, y, z])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_inverts_project() {
        let cam = Pinhole::new(1024, 768, 45.0, -0.05, 0.005);
        for (u, v) in [
            (0.0, 0.0),
            (512.0, 384.0),
            (1024.0, 768.0),
            (100.5, 700.25),
            (900.0, 20.0),
        ] {
            let d = cam.ray(u, v);
            let (pu, pv) = cam.project(&d).unwrap();
            assert!(
                (pu - u).abs() < 1e-9 && (pv - v).abs() < 1e-9,
                "{u},{v} -> {pu},{pv}"
            );
        }
    }
}
