//! The 10-20 and 10-10 EEG systems on the patient's own scalp, from the nasion, the inion and the
//! preauricular points, by the standard percentages.
//!
//! Each percentage is of a curve on the scalp in the plane through three points (Jurcak, Tsuzuki
//! and Dan 2007, "10/20, 10/10, and 10/5 systems revisited", their unambiguous construction),
//! not of a geodesic: the circumference through Fpz, T7 and Oz is not a shortest path, and the
//! shortest path from the nasion to the inion need not pass Cz. The construction:
//! 1. Cz halves both the nasion–inion curve through it and the LPA–RPA curve through it; it is
//!    found by alternating the two until it moves less than 0.01 mm.
//! 2. The midline (nasion–Cz–inion) gives Fpz, AFz, Fz, FCz, Cz, CPz, Pz, POz, Oz at 10 % steps;
//!    the central curve (LPA–Cz–RPA) T7, C5, C3, C1, Cz, C2, C4, C6, T8.
//! 3. Each half-circumference (Fpz–T7–Oz, Fpz–T8–Oz) is split at T7 (T8) and each part in
//!    fifths: Fp1, AF7, F7, FT7 before T7; TP7, P7, PO7, O1 after.
//! 4. Each row between the half-circumferences through the midline (F7–Fz–F8, …) is split at
//!    the midline and each half in quarters (F5, F3, F1 | F2, F4, F6); the AF and PO rows in
//!    halves (AF3, AF4, PO3, PO4).
//!
//! The positions below the circumference (T9, P9, Iz's row, …) are not placed. Frame: the image's
//! (RAS: x towards the patient's right, y anterior), metres.

use crate::NavError;
use crate::section::{Section, direction};
use mocomp_geom::nalgebra::Point3;
use mocomp_head::HeadShape;

/// How far from the scalp a landmark may lie, m: a landmark in the wrong frame or unit is
/// centimetres off or more; one picked on the scan is on the skin.
pub const MAX_OFF_SCALP_M: f64 = 0.015;

/// When Cz has settled, m.
const CZ_SETTLED_M: f64 = 1e-5;

/// The most alternations for Cz.
const CZ_ROUNDS: usize = 50;

/// The four landmarks the system is measured from, in the image's frame, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CranialLandmarks {
    /// The nasion.
    pub nasion: Point3<f64>,
    /// The inion.
    pub inion: Point3<f64>,
    /// The left preauricular point.
    pub lpa: Point3<f64>,
    /// The right preauricular point.
    pub rpa: Point3<f64>,
}

impl CranialLandmarks {
    fn named(&self) -> [(&'static str, Point3<f64>); 4] {
        [
            ("nasion", self.nasion),
            ("inion", self.inion),
            ("lpa", self.lpa),
            ("rpa", self.rpa),
        ]
    }
}

/// Which positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum System {
    /// The 21 positions of the 10-20 system (with Fpz and Oz, as MNE's montages).
    TenTwenty,
    /// The 61 positions of the 10-10 system on and above the circumference.
    TenTen,
}

impl std::str::FromStr for System {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "10-20" | "1020" => Ok(Self::TenTwenty),
            "10-10" | "1010" => Ok(Self::TenTen),
            _ => Err(format!("{s:?}: the system is 10-20 or 10-10")),
        }
    }
}

/// The 10-20 positions, in the order they are listed.
const TEN_TWENTY: [&str; 21] = [
    "Fp1", "Fpz", "Fp2", "F7", "F3", "Fz", "F4", "F8", "T7", "C3", "Cz", "C4", "T8", "P7", "P3",
    "Pz", "P4", "P8", "O1", "Oz", "O2",
];

/// A named position on the scalp, image frame, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EegPosition {
    /// Its name in the 10-10 nomenclature (T7, not T3).
    pub name: &'static str,
    /// Where it is on the scalp.
    pub point: Point3<f64>,
}

/// The positions of `system` on `scalp` (image frame), from its `landmarks`.
pub fn eeg_positions(
    scalp: &dyn HeadShape,
    landmarks: &CranialLandmarks,
    system: System,
) -> Result<Vec<EegPosition>, NavError> {
    check(scalp, landmarks)?;
    let all = ten_ten(scalp, landmarks)?;
    Ok(match system {
        System::TenTen => all,
        System::TenTwenty => all
            .into_iter()
            .filter(|p| TEN_TWENTY.contains(&p.name))
            .collect(),
    })
}

/// Every landmark finite, on the scalp, and left and right, front and back as RAS has them.
fn check(scalp: &dyn HeadShape, l: &CranialLandmarks) -> Result<(), NavError> {
    for (name, p) in l.named() {
        if !p.coords.iter().all(|c| c.is_finite()) {
            return Err(NavError::LandmarkNotFinite { name: name.into() });
        }
        let d = scalp.signed_distance(&p);
        if d.abs() > MAX_OFF_SCALP_M {
            return Err(NavError::LandmarkOffScalp {
                name: name.into(),
                distance_m: d,
                limit_m: MAX_OFF_SCALP_M,
            });
        }
    }
    let not_ras = |why: &str| {
        Err(NavError::LandmarksNotRas {
            why: why.to_string(),
        })
    };
    if l.rpa.x <= l.lpa.x {
        return not_ras("the right preauricular point is not to the right (+x) of the left");
    }
    if l.nasion.y <= l.inion.y {
        return not_ras("the nasion is not anterior (+y) of the inion");
    }
    Ok(())
}

/// All 61 positions, in the 10-10 system's order.
fn ten_ten(scalp: &dyn HeadShape, l: &CranialLandmarks) -> Result<Vec<EegPosition>, NavError> {
    let (midline, central) = settle_cz(scalp, l)?;
    let m = |share: f64| midline.at(share);
    let c = |share: f64| central.at(share);
    let (fpz, oz, t7, t8) = (m(0.1), m(0.9), c(0.1), c(0.9));
    let left = split(scalp, (&fpz, "Fpz"), (&t7, "T7"), (&oz, "Oz"), 5)?;
    let right = split(scalp, (&fpz, "Fpz"), (&t8, "T8"), (&oz, "Oz"), 5)?;
    // Index k of a half-circumference: 1..4 before T (Fp, AF, F, FT), 6..9 after (TP, P, PO, O).
    let row = |k: usize, mid: f64, a: &str, z: &str, parts: usize| {
        split(
            scalp,
            (&left[k], a),
            (&m(mid), "the midline"),
            (&right[k], z),
            parts,
        )
    };
    let af = row(2, 0.2, "AF7", "AF8", 2)?;
    let f = row(3, 0.3, "F7", "F8", 4)?;
    let fc = row(4, 0.4, "FT7", "FT8", 4)?;
    let cp = row(6, 0.6, "TP7", "TP8", 4)?;
    let p = row(7, 0.7, "P7", "P8", 4)?;
    let po = row(8, 0.8, "PO7", "PO8", 2)?;
    let at = |name: &'static str, point: Point3<f64>| EegPosition { name, point };
    let mut out = vec![at("Fp1", left[1]), at("Fpz", fpz), at("Fp2", right[1])];
    out.extend([at("AF7", left[2]), at("AF3", af[1]), at("AFz", m(0.2))]);
    out.extend([at("AF4", af[3]), at("AF8", right[2])]);
    let sevens = |rowp: &[Point3<f64>], names: [&'static str; 9], mid: f64| {
        names
            .into_iter()
            .enumerate()
            .map(|(i, n)| at(n, if i == 4 { m(mid) } else { rowp[i] }))
            .collect::<Vec<_>>()
    };
    out.extend(sevens(
        &f,
        ["F7", "F5", "F3", "F1", "Fz", "F2", "F4", "F6", "F8"],
        0.3,
    ));
    out.extend(sevens(
        &fc,
        [
            "FT7", "FC5", "FC3", "FC1", "FCz", "FC2", "FC4", "FC6", "FT8",
        ],
        0.4,
    ));
    let centre = ["T7", "C5", "C3", "C1", "Cz", "C2", "C4", "C6", "T8"];
    out.extend(
        centre
            .into_iter()
            .enumerate()
            .map(|(i, n)| at(n, c(0.1 * (i + 1) as f64))),
    );
    out.extend(sevens(
        &cp,
        [
            "TP7", "CP5", "CP3", "CP1", "CPz", "CP2", "CP4", "CP6", "TP8",
        ],
        0.6,
    ));
    out.extend(sevens(
        &p,
        ["P7", "P5", "P3", "P1", "Pz", "P2", "P4", "P6", "P8"],
        0.7,
    ));
    out.extend([at("PO7", left[8]), at("PO3", po[1]), at("POz", m(0.8))]);
    out.extend([at("PO4", po[3]), at("PO8", right[8])]);
    out.extend([at("O1", left[9]), at("Oz", oz), at("O2", right[9])]);
    Ok(out)
}

/// The midline and central curves through a Cz that halves both.
fn settle_cz(scalp: &dyn HeadShape, l: &CranialLandmarks) -> Result<(Section, Section), NavError> {
    let across = l.rpa - l.lpa;
    let along = l.nasion - l.inion;
    let up = direction(&across.cross(&along)).ok_or_else(|| NavError::LandmarksNotRas {
        why: "the preauricular line is parallel to the nasion–inion line".into(),
    })?;
    let centre =
        Point3::from((l.nasion.coords + l.inion.coords + l.lpa.coords + l.rpa.coords) / 4.0);
    let mut cz = centre + up * 0.2;
    let mut moved = f64::INFINITY;
    for _ in 0..CZ_ROUNDS {
        let midline = Section::new(scalp, &l.nasion, &l.inion, &cz, ("nasion", "inion"))?;
        let central = Section::new(scalp, &l.lpa, &l.rpa, &midline.at(0.5), ("lpa", "rpa"))?;
        let next = central.at(0.5);
        moved = (next - cz).norm();
        cz = next;
        if moved < CZ_SETTLED_M {
            let midline = Section::new(scalp, &l.nasion, &l.inion, &cz, ("nasion", "inion"))?;
            return Ok((midline, central));
        }
    }
    Err(NavError::CzUnsettled { moved_m: moved })
}

/// The curve from `a` through `via` to `z`, split at `via` and each half in `parts` equal parts:
/// the 2·parts + 1 points from `a` to `z`, `via`'s own place on the curve in the middle.
fn split(
    scalp: &dyn HeadShape,
    a: (&Point3<f64>, &str),
    via: (&Point3<f64>, &str),
    z: (&Point3<f64>, &str),
    parts: usize,
) -> Result<Vec<Point3<f64>>, NavError> {
    let curve = Section::new(scalp, a.0, z.0, via.0, (a.1, z.1))?;
    let s_via = curve.length_nearest(via.0);
    let total = curve.length();
    let mut out = Vec::with_capacity(2 * parts + 1);
    for i in 0..=parts {
        out.push(curve.at_length(s_via * i as f64 / parts as f64));
    }
    for i in 1..=parts {
        out.push(curve.at_length(s_via + (total - s_via) * i as f64 / parts as f64));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)] // test code
    use super::*;
    use mocomp_geom::nalgebra::{Isometry3, Vector3};
    use mocomp_head::Ellipsoid;

    /// A sphere of radius r about the origin with its landmarks on the equator.
    fn sphere(r: f64) -> (Ellipsoid, CranialLandmarks) {
        let s = Ellipsoid::new(Isometry3::identity(), Vector3::new(r, r, r)).unwrap();
        let l = CranialLandmarks {
            nasion: Point3::new(0.0, r, 0.0),
            inion: Point3::new(0.0, -r, 0.0),
            lpa: Point3::new(-r, 0.0, 0.0),
            rpa: Point3::new(r, 0.0, 0.0),
        };
        (s, l)
    }

    fn find(ps: &[EegPosition], name: &str) -> Point3<f64> {
        ps.iter().find(|p| p.name == name).expect(name).point
    }

    #[test]
    fn on_a_sphere_the_positions_sit_at_their_textbook_angles() {
        let r = 0.09;
        let (s, l) = sphere(r);
        let ps = eeg_positions(&s, &l, System::TenTen).unwrap();
        assert_eq!(ps.len(), 61);
        let mut names: Vec<_> = ps.iter().map(|p| p.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), 61, "a name twice");
        let deg = |a: f64| a.to_radians();
        let on = |az: f64, el: f64| {
            Point3::new(
                r * deg(el).cos() * deg(az).sin(),
                r * deg(el).cos() * deg(az).cos(),
                r * deg(el).sin(),
            )
        };
        // On a sphere with the landmarks on the equator the 10 % steps are 18° apart.
        for (name, want) in [
            ("Cz", Point3::new(0.0, 0.0, r)),
            ("Fz", on(0.0, 54.0)),
            ("Fpz", on(0.0, 18.0)),
            ("C3", on(-90.0, 54.0)),
            ("T8", on(90.0, 18.0)),
            ("F7", on(-54.0, 18.0)),
            ("O2", on(162.0, 18.0)),
        ] {
            let got = find(&ps, name);
            assert!((got - want).norm() < 2e-4, "{name}: {got} against {want}");
        }
        // F3 halves the F7–Fz curve.
        let (f7, f3, fz) = (find(&ps, "F7"), find(&ps, "F3"), find(&ps, "Fz"));
        let angle = |a: Point3<f64>, b: Point3<f64>| a.coords.angle(&b.coords);
        assert!((angle(f7, f3) - angle(f3, fz)).abs() < 2e-3);
        for p in &ps {
            assert!(
                (p.point.coords.norm() - r).abs() < 1e-6,
                "{} off the sphere",
                p.name
            );
        }
        let twenty = eeg_positions(&s, &l, System::TenTwenty).unwrap();
        assert_eq!(twenty.len(), 21);
        assert_eq!(twenty[4].name, "F3");
        assert_eq!(twenty[4].point, find(&ps, "F3"));
    }

    #[test]
    fn landmarks_off_the_scalp_or_mirrored_are_refused_by_name() {
        let (s, l) = sphere(0.09);
        let mut mm = l;
        mm.inion *= 1000.0;
        let e = eeg_positions(&s, &mm, System::TenTwenty).unwrap_err();
        assert!(
            matches!(e, NavError::LandmarkOffScalp { ref name, .. } if name == "inion"),
            "{e}"
        );
        assert!(e.to_string().contains("units"), "{e}");
        let swapped = CranialLandmarks {
            lpa: l.rpa,
            rpa: l.lpa,
            ..l
        };
        let e = eeg_positions(&s, &swapped, System::TenTwenty).unwrap_err();
        assert!(matches!(e, NavError::LandmarksNotRas { .. }), "{e}");
        let mut nan = l;
        nan.lpa.x = f64::NAN;
        assert!(matches!(
            eeg_positions(&s, &nan, System::TenTwenty),
            Err(NavError::LandmarkNotFinite { .. })
        ));
        assert_eq!("10-10".parse::<System>(), Ok(System::TenTen));
        assert!("10-5".parse::<System>().is_err());
    }
}
