//! Camera intrinsics: pinhole with Brown–Conrady distortion in its rational form (OpenCV's
//! 8-coefficient model `k1, k2, p1, p2, k3, k4, k5, k6`, which the Azure Kinect SDK's factory
//! calibration uses; with k4 = k5 = k6 = 0 it is the 5-coefficient model of the Kinect v2), and
//! the pixel-centre convention.
//!
//! Pixel coordinates `(u, v)` in this crate are *index* coordinates: the centre of the pixel in
//! column `c`, row `r` is at `(c, r)`. Intrinsics state where their principal point is measured
//! from with [`PixelCentre`]: `integer` (OpenCV's convention: pixel centres at integers) or
//! `half` (pixel centres at `c + 0.5`, as libfreenect2's `getPointXYZ` uses).

use crate::error::VisionError;
use mocomp_geom::nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Where pixel centres lie in the intrinsics' coordinates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PixelCentre {
    /// Pixel `(c, r)` is centred at `(c, r)` (OpenCV).
    #[default]
    Integer,
    /// Pixel `(c, r)` is centred at `(c + 0.5, r + 0.5)` (libfreenect2).
    Half,
}

impl PixelCentre {
    fn offset(self) -> f64 {
        match self {
            PixelCentre::Integer => 0.0,
            PixelCentre::Half => 0.5,
        }
    }
}

/// Intrinsics of a depth/IR camera (pixels; distortion dimensionless).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Radial distortion k1.
    #[serde(default)]
    pub k1: f64,
    /// Radial distortion k2.
    #[serde(default)]
    pub k2: f64,
    /// Radial distortion k3.
    #[serde(default)]
    pub k3: f64,
    /// Rational radial distortion k4 (the denominator's r² term).
    #[serde(default)]
    pub k4: f64,
    /// Rational radial distortion k5 (r⁴).
    #[serde(default)]
    pub k5: f64,
    /// Rational radial distortion k6 (r⁶).
    #[serde(default)]
    pub k6: f64,
    /// Tangential distortion p1.
    #[serde(default)]
    pub p1: f64,
    /// Tangential distortion p2.
    #[serde(default)]
    pub p2: f64,
    /// Pixel-centre convention of `cx`, `cy`.
    #[serde(default)]
    pub pixel_centre: PixelCentre,
}

impl Intrinsics {
    /// Typical Kinect v2 IR intrinsics (one device's factory values, widely copied; libfreenect2
    /// convention): 512×424, fx = fy = 365.456, cx = 254.878, cy = 205.395, k1 = 0.0905474,
    /// k2 = −0.26819, k3 = 0.0950862.
    pub fn kinect_v2() -> Self {
        Self {
            width: 512,
            height: 424,
            fx: 365.456,
            fy: 365.456,
            cx: 254.878,
            cy: 205.395,
            k1: 0.0905474,
            k2: -0.26819,
            k3: 0.0950862,
            k4: 0.0,
            k5: 0.0,
            k6: 0.0,
            p1: 0.0,
            p2: 0.0,
            pixel_centre: PixelCentre::Half,
        }
    }

    /// Parses TOML (keys as the fields; distortion and `pixel_centre` optional) and validates.
    pub fn from_toml_str(text: &str, what: &str) -> Result<Self, VisionError> {
        let i: Self = toml::from_str(text).map_err(|e| VisionError::Config {
            what: what.to_string(),
            message: e.to_string().trim_end().replace('\n', " "),
        })?;
        i.validate(what)?;
        Ok(i)
    }

    /// Checks sizes and focal lengths are positive and everything is finite.
    pub fn validate(&self, what: &str) -> Result<(), VisionError> {
        let bad = |m: String| VisionError::Config {
            what: what.to_string(),
            message: m,
        };
        if self.width == 0 || self.height == 0 {
            return Err(bad(format!(
                "image size {}×{} is empty",
                self.width, self.height
            )));
        }
        for (name, v) in [
            ("fx", self.fx),
            ("fy", self.fy),
            ("cx", self.cx),
            ("cy", self.cy),
            ("k1", self.k1),
            ("k2", self.k2),
            ("k3", self.k3),
            ("k4", self.k4),
            ("k5", self.k5),
            ("k6", self.k6),
            ("p1", self.p1),
            ("p2", self.p2),
        ] {
            if !v.is_finite() {
                return Err(bad(format!("{name} is not a finite number")));
            }
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(bad(format!(
                "focal lengths must be positive (fx {}, fy {})",
                self.fx, self.fy
            )));
        }
        Ok(())
    }

    /// The radial factor at squared radius `r2`: (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴
    /// + k6 r⁶).
    #[inline]
    fn radial(&self, r2: f64) -> f64 {
        (1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3)))
            / (1.0 + r2 * (self.k4 + r2 * (self.k5 + r2 * self.k6)))
    }

    /// The coefficients in OpenCV's order: `k1, k2, p1, p2, k3, k4, k5, k6`.
    pub fn opencv_distortion(&self) -> [f64; 8] {
        [
            self.k1, self.k2, self.p1, self.p2, self.k3, self.k4, self.k5, self.k6,
        ]
    }

    /// Applies the distortion model to normalised coordinates.
    #[inline]
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let radial = self.radial(r2);
        (
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// The radial factor and its derivative with respect to r².
    #[inline]
    fn radial_and_slope(&self, r2: f64) -> (f64, f64) {
        let a = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let b = 1.0 + r2 * (self.k4 + r2 * (self.k5 + r2 * self.k6));
        let da = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
        let db = self.k4 + r2 * (2.0 * self.k5 + 3.0 * r2 * self.k6);
        (a / b, (da * b - a * db) / (b * b))
    }

    /// Removes the distortion from normalised coordinates: Newton's method on the distortion
    /// (its Jacobian in closed form), each step halved until it brings the point closer. The
    /// fixed-point iteration OpenCV's `undistortPoints` uses fails to converge in the corners of
    /// strongly distorted rational lenses (the Azure Kinect's family); this converges to 1e-15
    /// wherever the lens maps onto the point, in a handful of steps.
    #[inline]
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        let residual = |x: f64, y: f64| {
            let (dx, dy) = self.distort(x, y);
            (dx - xd, dy - yd)
        };
        let (mut x, mut y) = (xd, yd);
        let (mut fx, mut fy) = residual(x, y);
        for _ in 0..50 {
            let err = fx.hypot(fy);
            if err < 1e-15 {
                break;
            }
            let r2 = x * x + y * y;
            let (r, dr) = self.radial_and_slope(r2);
            let (p1, p2) = (self.p1, self.p2);
            let j11 = r + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x;
            let j12 = 2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y;
            let j22 = r + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x;
            let det = j11 * j22 - j12 * j12;
            if det.abs() < 1e-300 || !det.is_finite() {
                break;
            }
            let sx = -(j22 * fx - j12 * fy) / det;
            let sy = -(j11 * fy - j12 * fx) / det;
            let mut t = 1.0;
            let mut improved = false;
            for _ in 0..30 {
                let (nx, ny) = (x + t * sx, y + t * sy);
                let (gx, gy) = residual(nx, ny);
                if gx.hypot(gy) < err {
                    (x, y, fx, fy) = (nx, ny, gx, gy);
                    improved = true;
                    break;
                }
                t *= 0.5;
            }
            if !improved {
                break;
            }
        }
        (x, y)
    }

    /// Projects a camera-frame point (metres, z forward) to pixel index coordinates.
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        if p.z <= 0.0 {
            return None;
        }
        let (xd, yd) = self.distort(p.x / p.z, p.y / p.z);
        let o = self.pixel_centre.offset();
        Some((self.fx * xd + self.cx - o, self.fy * yd + self.cy - o))
    }

    /// The camera-frame point at pixel index coordinates `(u, v)` and depth `z` (metres, along the
    /// optical axis, as Kinect depth is).
    pub fn unproject(&self, u: f64, v: f64, z: f64) -> Vector3<f64> {
        let o = self.pixel_centre.offset();
        let (x, y) = self.undistort((u + o - self.cx) / self.fx, (v + o - self.cy) / self.fy);
        Vector3::new(x * z, y * z, z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_unproject_round_trip() {
        let k = Intrinsics::kinect_v2();
        for &(x, y, z) in &[
            (0.0, 0.0, 1.0),
            (0.3, -0.2, 0.9),
            (-0.6, 0.45, 1.2),
            (0.01, 0.5, 2.0),
        ] {
            let p = Vector3::new(x, y, z);
            let (u, v) = k.project(&p).unwrap();
            let back = k.unproject(u, v, z);
            assert!((back - p).norm() < 1e-12, "{p} -> ({u}, {v}) -> {back}");
        }
        assert!(k.project(&Vector3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn the_rational_model_round_trips_over_the_whole_image() {
        // An Azure Kinect's NFOV unbinned calibration (strong rational distortion).
        let k = Intrinsics {
            width: 640,
            height: 576,
            fx: 504.6,
            fy: 504.7,
            cx: 332.8,
            cy: 348.8,
            k1: 0.548,
            k2: -0.021,
            k3: -0.00265,
            k4: 0.890,
            k5: 0.0861,
            k6: -0.0139,
            p1: 2.1e-5,
            p2: -7.2e-5,
            pixel_centre: PixelCentre::Integer,
        };
        for r in 0..=24 {
            for c in 0..=25 {
                let (u, v) = (f64::from(c) * 639.0 / 25.0, f64::from(r) * 575.0 / 24.0);
                let p = k.unproject(u, v, 0.8);
                let (pu, pv) = k.project(&p).unwrap();
                assert!(
                    (pu - u).abs() < 1e-9 && (pv - v).abs() < 1e-9,
                    "({u}, {v}) -> {p} -> ({pu}, {pv})"
                );
            }
        }
    }

    #[test]
    fn pixel_centre_convention_shifts_by_half_a_pixel() {
        let mut k = Intrinsics::kinect_v2();
        let p = Vector3::new(0.0, 0.0, 1.0);
        let (u_half, _) = k.project(&p).unwrap();
        k.pixel_centre = PixelCentre::Integer;
        let (u_int, _) = k.project(&p).unwrap();
        assert!((u_int - u_half - 0.5).abs() < 1e-12);
        assert!((u_int - 254.878).abs() < 1e-12);
    }

    #[test]
    fn toml_is_validated() {
        let ok = "width = 512\nheight = 424\nfx = 365.4\nfy = 365.4\ncx = 255.0\ncy = 205.0\n";
        assert!(Intrinsics::from_toml_str(ok, "i.toml").is_ok());
        assert!(
            Intrinsics::from_toml_str(&format!("{ok}k4 = 0.1\nk6 = -0.01\n"), "i.toml").is_ok()
        );
        let e = Intrinsics::from_toml_str(&format!("{ok}k7 = 0.1\n"), "i.toml").unwrap_err();
        assert!(e.to_string().contains("k7"), "{e}");
        let e =
            Intrinsics::from_toml_str(&ok.replace("fx = 365.4", "fx = -1"), "i.toml").unwrap_err();
        assert!(e.to_string().contains("positive"), "{e}");
        let e = Intrinsics::from_toml_str(&ok.replace("width = 512", "width = 0"), "i.toml")
            .unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
    }
}
