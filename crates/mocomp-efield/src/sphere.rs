//! The electric field a coil's changing current induces inside a conducting sphere, for
//! magnetic dipoles outside it (Heller and van Hulsteyn 1992, Biophys J 61:1181, eq. 14 and
//! appendix; the form SimNIBS's `analytical_solutions.tms_E_field` computes). With `r` the
//! point and `r₀` a dipole of moment `m`, both from the sphere's centre, `a = r₀ − r`:
//!
//! ```text
//! F  = |a| (|r₀| |a| + r₀·a)
//! ∇F = (|a|²/|r₀| + 2|a| + 2|r₀| + r₀·a/|a|) r₀ − (|a| + 2|r₀| + r₀·a/|a|) r
//! E  = −(μ₀/4π) dI/dt Σ [F (r × m) − (m·∇F) (r × r₀)] / F²
//! ```
//!
//! Exact for a sphere of any radial conductivity profile (the charges on its surface cancel
//! the radial field; the conductivity drops out), so the field has no component along `r`.
//!
//! The dipoles are placed once per coil pose ([`PlacedCoil::place`], into buffers kept from the
//! last pose), then each point costs one pass over them with no allocation: the arrays are laid
//! out one coordinate at a time so the pass compiles to vector instructions.

use crate::ccd::DipoleCoil;
use crate::error::EfieldError;
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};

/// μ₀ / 4π, T·m/A.
const MU0_OVER_4PI: f64 = 1e-7;
/// Dipoles summed side by side (four f64: two SSE2 registers, one AVX register).
const LANES: usize = 4;

/// A sphere: the head under the coil, as the field sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Its centre (head frame), m.
    pub centre: Point3<f64>,
    /// Its radius, m.
    pub radius: f64,
}

impl Sphere {
    /// A sphere at `centre` of `radius` (positive, finite).
    pub fn new(centre: Point3<f64>, radius: f64) -> Result<Self, EfieldError> {
        if radius.is_finite() && radius > 0.0 && centre.coords.iter().all(|c| c.is_finite()) {
            Ok(Self { centre, radius })
        } else {
            Err(EfieldError::BadSphere {
                centre_m: centre.coords.into(),
                radius_m: radius,
            })
        }
    }
}

/// A coil's dipoles at one pose, relative to one sphere's centre, laid out for the field's pass.
#[derive(Debug, Clone, Default)]
pub struct PlacedCoil {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    mx: Vec<f64>,
    my: Vec<f64>,
    mz: Vec<f64>,
    /// |r₀| of each.
    norm: Vec<f64>,
    /// The sphere they are placed about.
    sphere: Option<Sphere>,
    /// The least |r₀| over the dipoles, m.
    nearest: f64,
    /// How many of the entries are the coil's (the rest pad to whole chunks).
    dipoles: usize,
}

impl PlacedCoil {
    /// Buffers for a coil of `n` dipoles (placing it then allocates nothing).
    pub fn with_capacity(n: usize) -> Self {
        let v = || Vec::with_capacity(n.next_multiple_of(LANES));
        Self {
            x: v(),
            y: v(),
            z: v(),
            mx: v(),
            my: v(),
            mz: v(),
            norm: v(),
            sphere: None,
            nearest: f64::INFINITY,
            dipoles: 0,
        }
    }

    /// Places `coil` at `head_from_coil` about `sphere`, reusing the buffers (no allocation
    /// once they have held a coil this size). Refused when a dipole is not outside the sphere.
    pub fn place(
        &mut self,
        coil: &DipoleCoil,
        head_from_coil: &Isometry3<f64>,
        sphere: &Sphere,
    ) -> Result<(), EfieldError> {
        let n = coil.len();
        let padded = n.next_multiple_of(LANES);
        for v in [
            &mut self.x,
            &mut self.y,
            &mut self.z,
            &mut self.mx,
            &mut self.my,
            &mut self.mz,
            &mut self.norm,
        ] {
            v.clear();
            v.resize(padded, 0.0);
        }
        let mut nearest = f64::INFINITY;
        // A pose or coil that is not finite places no dipole anywhere: a NaN or infinity
        // anywhere makes this sum so, and the placement is refused below.
        let mut check = 0.0;
        // The rotation as a matrix once: a quaternion per dipole costs twice as much.
        let rot = head_from_coil.rotation.to_rotation_matrix();
        let shift = head_from_coil.translation.vector - sphere.centre.coords;
        for (k, (p, m)) in coil.positions.iter().zip(&coil.moments).enumerate() {
            let r0 = rot * p + shift;
            let m = rot * m;
            let d = r0.norm();
            nearest = nearest.min(d);
            check += d + m.x + m.y + m.z;
            (self.x[k], self.y[k], self.z[k]) = (r0.x, r0.y, r0.z);
            (self.mx[k], self.my[k], self.mz[k]) = (m.x, m.y, m.z);
            self.norm[k] = d;
        }
        // The padding: the last dipole's place with no moment, whose terms are zero.
        if let Some(last) = n.checked_sub(1) {
            for k in n..padded {
                (self.x[k], self.y[k], self.z[k]) = (self.x[last], self.y[last], self.z[last]);
                self.norm[k] = self.norm[last];
            }
        }
        let finite = check.is_finite();
        self.dipoles = coil.len();
        self.nearest = nearest;
        self.sphere = Some(*sphere);
        if !finite {
            self.sphere = None;
            return Err(EfieldError::Outside {
                what: "a coil pose or dipole that is not finite".into(),
            });
        }
        // (`nearest` is finite here: checked above.)
        if nearest <= sphere.radius {
            self.sphere = None;
            return Err(EfieldError::Outside {
                what: format!(
                    "a dipole of the coil {:.1} mm from the sphere's centre, inside its radius \
                     of {:.1} mm",
                    nearest * 1e3,
                    sphere.radius * 1e3
                ),
            });
        }
        Ok(())
    }

    /// How many dipoles are placed.
    pub fn len(&self) -> usize {
        self.dipoles
    }

    /// Whether none are.
    pub fn is_empty(&self) -> bool {
        self.dipoles == 0
    }

    /// The field at `at` (head frame, m), V/m, for a coil current changing at `didt` A/s.
    /// Refused for a point not inside the sphere (or a coil not placed).
    pub fn e_field(&self, at: &Point3<f64>, didt: f64) -> Result<Vector3<f64>, EfieldError> {
        let Some(sphere) = self.sphere else {
            return Err(EfieldError::Outside {
                what: "no coil placed".into(),
            });
        };
        let r = at - sphere.centre;
        if r.norm() >= sphere.radius || !r.norm().is_finite() {
            return Err(EfieldError::Outside {
                what: format!(
                    "the point {:.1} mm from the sphere's centre, beyond its radius of {:.1} mm",
                    r.norm() * 1e3,
                    sphere.radius * 1e3
                ),
            });
        }
        Ok(self.sum(&r) * (-didt * MU0_OVER_4PI))
    }

    /// Σ [F (r × m) − (m·∇F) (r × r₀)] / F² over the dipoles, `r` from the sphere's centre.
    ///
    /// [`LANES`] dipoles at a time into as many partial sums: a floating-point sum is not
    /// reordered by the compiler, so one running sum would keep the pass scalar; independent
    /// lanes let it use vector instructions. The buffers are padded to whole chunks with
    /// dipoles of no moment, which add exactly zero.
    fn sum(&self, r: &Vector3<f64>) -> Vector3<f64> {
        let (rx, ry, rz) = (r.x, r.y, r.z);
        let mut acc = [[0.0f64; LANES]; 3];
        let chunks = self
            .x
            .chunks_exact(LANES)
            .zip(self.y.chunks_exact(LANES))
            .zip(self.z.chunks_exact(LANES))
            .zip(self.mx.chunks_exact(LANES))
            .zip(self.my.chunks_exact(LANES))
            .zip(self.mz.chunks_exact(LANES))
            .zip(self.norm.chunks_exact(LANES));
        for ((((((x, y), z), mx), my), mz), norm) in chunks {
            for k in 0..LANES {
                let (x0, y0, z0, n0) = (x[k], y[k], z[k], norm[k]);
                let (ax, ay, az) = (x0 - rx, y0 - ry, z0 - rz);
                let na = (ax * ax + ay * ay + az * az).sqrt();
                let r0a = x0 * ax + y0 * ay + z0 * az;
                let f = na * (n0 * na + r0a);
                let r0a_na = r0a / na;
                let c0 = na * na / n0 + 2.0 * na + 2.0 * n0 + r0a_na;
                let c1 = na + 2.0 * n0 + r0a_na;
                // m·∇F without forming ∇F.
                let m_r0 = mx[k] * x0 + my[k] * y0 + mz[k] * z0;
                let m_r = mx[k] * rx + my[k] * ry + mz[k] * rz;
                let mg = c0 * m_r0 - c1 * m_r;
                let inv_f2 = 1.0 / (f * f);
                // F (r × m) − (m·∇F) (r × r₀), a component at a time.
                acc[0][k] += (f * (ry * mz[k] - rz * my[k]) - mg * (ry * z0 - rz * y0)) * inv_f2;
                acc[1][k] += (f * (rz * mx[k] - rx * mz[k]) - mg * (rz * x0 - rx * z0)) * inv_f2;
                acc[2][k] += (f * (rx * my[k] - ry * mx[k]) - mg * (rx * y0 - ry * x0)) * inv_f2;
            }
        }
        let total = |lanes: &[f64; LANES]| lanes.iter().sum::<f64>();
        Vector3::new(total(&acc[0]), total(&acc[1]), total(&acc[2]))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::test_coil::eight;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};
    use proptest::prelude::*;

    /// The coil over the top of a 90 mm sphere at the origin, face 5 mm off it, turned `spin`.
    fn over_top(spin: f64) -> Isometry3<f64> {
        // Coil +z into the head: pointing down.
        Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.095),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), spin)
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        )
    }

    fn sphere() -> Sphere {
        Sphere::new(Point3::origin(), 0.09).unwrap()
    }

    #[test]
    fn the_field_under_a_figure_of_eight_is_tangential_and_strongest_under_its_centre() {
        let coil = eight();
        let mut placed = PlacedCoil::default();
        placed.place(&coil, &over_top(0.0), &sphere()).unwrap();
        let at = |z: f64| placed.e_field(&Point3::new(0.0, 0.0, z), 1e8).unwrap();
        let shallow = at(0.075);
        let deep = at(0.06);
        // Under the centre the field runs as the windings do where the wings meet: across the
        // line of the wings (the coil's y), opposite to the current.
        assert!(
            shallow.y.abs() > 10.0 * shallow.x.abs().max(shallow.z.abs()),
            "{shallow}"
        );
        assert!(shallow.norm() > deep.norm(), "{shallow} {deep}");
        // Figures of the size TMS gives at 1e8 A/s: tens to hundreds of V/m.
        assert!(
            shallow.norm() > 10.0 && shallow.norm() < 1000.0,
            "{shallow}"
        );
        // At the centre of the sphere, nothing.
        assert!(at(0.0).norm() < 1e-12);
    }

    #[test]
    fn points_outside_and_coils_inside_are_refused() {
        let coil = eight();
        let mut placed = PlacedCoil::default();
        placed.place(&coil, &over_top(0.0), &sphere()).unwrap();
        assert!(placed.e_field(&Point3::new(0.0, 0.0, 0.091), 1e8).is_err());
        let sunk = Isometry3::translation(0.0, 0.0, -0.02) * over_top(0.0);
        let e = placed.place(&coil, &sunk, &sphere()).unwrap_err();
        assert!(e.to_string().contains("inside its radius"), "{e}");
        // And nothing is computed from a refused placement.
        assert!(placed.e_field(&Point3::new(0.0, 0.0, 0.05), 1e8).is_err());
        let lost = Isometry3::translation(f64::NAN, 0.0, 0.0) * over_top(0.0);
        let e = placed.place(&coil, &lost, &sphere()).unwrap_err();
        assert!(e.to_string().contains("not finite"), "{e}");
        assert!(Sphere::new(Point3::origin(), 0.0).is_err());
        assert!(Sphere::new(Point3::new(f64::NAN, 0.0, 0.0), 0.09).is_err());
    }

    #[test]
    fn placing_again_allocates_nothing() {
        let coil = eight();
        let mut placed = PlacedCoil::with_capacity(coil.len());
        let before = placed.x.as_ptr();
        for k in 0..10 {
            placed
                .place(&coil, &over_top(0.1 * k as f64), &sphere())
                .unwrap();
        }
        assert_eq!(placed.x.as_ptr(), before);
        assert_eq!(placed.len(), coil.len());
    }

    #[test]
    fn a_coil_s_field_is_the_sum_of_its_dipoles_fields_whatever_their_number() {
        // 1 to 9 dipoles: every remainder of the chunks the pass works in.
        let all = eight();
        let s = sphere();
        let at = Point3::new(0.004, -0.007, 0.07);
        for n in 1..10 {
            let coil = DipoleCoil {
                positions: all.positions[..n].to_vec(),
                moments: all.moments[..n].to_vec(),
                ..all.clone()
            };
            let mut whole = PlacedCoil::default();
            whole.place(&coil, &over_top(0.2), &s).unwrap();
            assert_eq!(whole.len(), n);
            let mut sum = Vector3::zeros();
            for k in 0..n {
                let one = DipoleCoil {
                    positions: vec![coil.positions[k]],
                    moments: vec![coil.moments[k]],
                    ..all.clone()
                };
                let mut placed = PlacedCoil::default();
                placed.place(&one, &over_top(0.2), &s).unwrap();
                sum += placed.e_field(&at, 1e8).unwrap();
            }
            let e = whole.e_field(&at, 1e8).unwrap();
            assert!(
                (e - sum).norm() <= 1e-12 * sum.norm(),
                "{n}: {e} against {sum}"
            );
            assert!(e.norm() > 0.0);
        }
    }

    proptest! {
        /// Inside a sphere the induced field has no radial part, whatever the coil's pose
        /// over it, the point, and the sphere's place.
        #[test]
        fn the_field_is_tangential_to_the_sphere(
            spin in -3.1f64..3.1, tilt in -0.5f64..0.5, lift in 0.0f64..0.03,
            px in -0.05f64..0.05, py in -0.05f64..0.05, pz in -0.05f64..0.05,
            cx in -0.1f64..0.1, cy in -0.1f64..0.1, cz in -0.1f64..0.1,
        ) {
            let c = Vector3::new(cx, cy, cz);
            let pose = Isometry3::from_parts(Translation3::from(c), UnitQuaternion::identity())
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), tilt)
                * Isometry3::translation(0.0, 0.0, lift)
                * over_top(spin);
            let s = Sphere::new(Point3::from(c), 0.09).unwrap();
            let mut placed = PlacedCoil::default();
            placed.place(&eight(), &pose, &s).unwrap();
            let at = Point3::from(c + Vector3::new(px, py, pz));
            let e = placed.e_field(&at, 1e8).unwrap();
            let radial = e.dot(&(at - s.centre).normalize());
            prop_assert!(radial.abs() <= 1e-9 * e.norm().max(1e-12), "{} of {}", radial, e.norm());
        }

        /// Turning the coil and the point together about the sphere's centre turns the field
        /// with them; doubling dI/dt doubles it.
        #[test]
        fn the_field_turns_with_the_coil_and_scales_with_the_current(
            ax in -1.0f64..1.0, ay in -1.0f64..1.0, az in -1.0f64..1.0, angle in -3.0f64..3.0,
            px in -0.04f64..0.04, py in -0.04f64..0.04, pz in 0.0f64..0.06,
        ) {
            let axis = Vector3::new(ax, ay, az);
            prop_assume!(axis.norm() > 0.1);
            let turn = UnitQuaternion::from_axis_angle(&mocomp_geom::nalgebra::Unit::new_normalize(axis), angle);
            let s = sphere();
            let at = Point3::new(px, py, pz);
            let mut a = PlacedCoil::default();
            a.place(&eight(), &over_top(0.3), &s).unwrap();
            let mut b = PlacedCoil::default();
            b.place(&eight(), &(Isometry3::from_parts(Translation3::identity(), turn) * over_top(0.3)), &s).unwrap();
            let ea = a.e_field(&at, 1e8).unwrap();
            let eb = b.e_field(&(turn * at), 1e8).unwrap();
            prop_assert!((turn * ea - eb).norm() <= 1e-9 * ea.norm().max(1e-9));
            let e2 = a.e_field(&at, 2e8).unwrap();
            prop_assert!((e2 - 2.0 * ea).norm() <= 1e-12 * ea.norm().max(1e-9));
        }
    }
}
