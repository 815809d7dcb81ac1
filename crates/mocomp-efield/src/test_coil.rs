//! A small coil for the unit tests (SimNIBS's own are in `tests/data/coils/`).

use crate::ccd::DipoleCoil;
use mocomp_geom::nalgebra::Vector3;

/// A small figure-of-eight: two rings of dipoles, opposite moments, 10 mm behind the face
/// (each wing ten turns of 15 mm radius, 7e-3 m², over its twelve dipoles).
pub(crate) fn eight() -> DipoleCoil {
    let mut positions = Vec::new();
    let mut moments = Vec::new();
    for (cx, sign) in [(-0.025, 1.0), (0.025, -1.0)] {
        for k in 0..12 {
            let a = std::f64::consts::TAU * k as f64 / 12.0;
            positions.push(Vector3::new(cx + 0.015 * a.cos(), 0.015 * a.sin(), -0.01));
            moments.push(Vector3::new(0.0, 0.0, sign * 5e-4));
        }
    }
    DipoleCoil {
        name: None,
        didt_max_a_per_s: Some(1e8),
        positions,
        moments,
    }
}
