//! Camera intrinsics: pinhole with Brown–Conrady distortion, and the pixel-centre convention.
//!
//! Pixel coordinates `(u, v)` in this crate are *index* coordinates: the centre of the pixel in
//! column `c`, row `r` is at `(c, r)`. Intrinsics state where their principal point is measured
//! from with [`PixelCentre`]: `integer` (OpenCV's convention: pixel centres at integers) or
//! `half` (pixel centres at `c + 0.5`, as libfreenect2's `getPointXYZ` uses).

use crate::error::VisionError;
use mocomp_geom::nalgebra::Vector3;
use serde::Deserialize;

/// Where pixel centres lie in the intrinsics' coordinates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
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
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
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

    /// Applies the distortion model to normalised coordinates.
    #[inline]
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        (
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// Removes the distortion from normalised coordinates (fixed-point iteration, as OpenCV's
    /// `undistortPoints`; converges to 1e-12 within the image for Kinect-like distortion).
    #[inline]
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        let (mut x, mut y) = (xd, yd);
        for _ in 0..20 {
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
            let dx = 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x);
            let dy = self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y;
            let (nx, ny) = ((xd - dx) / radial, (yd - dy) / radial);
            let change = (nx - x).abs() + (ny - y).abs();
            x = nx;
            y = ny;
            if change < 1e-14 {
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
        let e = Intrinsics::from_toml_str(&format!("{ok}k4 = 0.1\n"), "i.toml").unwrap_err();
        assert!(e.to_string().contains("k4"), "{e}");
        let e =
            Intrinsics::from_toml_str(&ok.replace("fx = 365.4", "fx = -1"), "i.toml").unwrap_err();
        assert!(e.to_string().contains("positive"), "{e}");
        let e = Intrinsics::from_toml_str(&ok.replace("width = 512", "width = 0"), "i.toml")
            .unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
    }
}
