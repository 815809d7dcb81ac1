//! The prediction study of issues 16 and 33: how far the predicted head puts the coil from where
//! the head really puts it, for the filter before issue 16 (constant velocity), today's filter
//! alone (constant acceleration, an interacting-multiple-model filter over three noise levels) and
//! the default (that filter blended with the prediction learned from the head's own motion), at
//! horizons of 30–80 ms, on the patient studies' fast nods, the demo's random motion and a
//! replayed trace.
//!
//! The tracker is modelled as in the demo: 60 Hz, 0.1 mm and 1 mrad of Gaussian noise per axis
//! (seeded). The error is measured at the coil's centre, 113 mm from the head marker on its z
//! axis, where the demo puts the coil. Run:
//!
//! ```text
//! cargo run --release -p mocomp-sim --example prediction_study [-- TRACE.csv]
//! ```
//!
//! To compare other settings, `VARIANTS` lists `[predictor]` settings, `;` between variants and
//! `,` between keys (`VARIANTS='learned=false;jerk_noise=0.3' …`); `NOISE` scales the tracker's
//! noise (`NOISE=0` for none).

#![allow(clippy::print_stdout)] // a study: its output is the table it prints

use mocomp_control::{PosePredictor, PredictorConfig};
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use mocomp_sim::HeadMotion;
use mocomp_sim::motion::{Nods, RandomMotion};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

const RATE_HZ: f64 = 60.0;
const SECONDS: f64 = 30.0;
const HORIZONS_MS: [f64; 4] = [30.0, 50.0, 65.0, 80.0];

/// RMS and maximum of the coil-centre error (mm) per horizon.
fn study(
    motion: &HeadMotion,
    cfg: PredictorConfig,
    seed: u64,
    noise_scale: f64,
) -> Result<Vec<(f64, f64)>, rand_distr::NormalError> {
    let traj = motion.trajectory();
    let coil = Point3::new(0.0, 0.0, 0.113);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let pos = Normal::new(0.0, 1e-4 * noise_scale)?;
    let rot = Normal::new(0.0, 1e-3 * noise_scale)?;
    let mut f = PosePredictor::new(cfg);
    let mut sums = vec![(0.0, 0.0, 0usize); HORIZONS_MS.len()];
    let n = (SECONDS * RATE_HZ) as usize;
    for k in 0..n {
        let t = k as f64 / RATE_HZ;
        let truth = traj.rest_from_head(t);
        let noise = Isometry3::from_parts(
            Translation3::new(
                pos.sample(&mut rng),
                pos.sample(&mut rng),
                pos.sample(&mut rng),
            ),
            UnitQuaternion::from_scaled_axis(Vector3::new(
                rot.sample(&mut rng),
                rot.sample(&mut rng),
                rot.sample(&mut rng),
            )),
        );
        f.update(t, &(noise * truth));
        // Skip the start: the motions begin at 1 s with a jump in speed no filter predicts.
        if t < 2.5 {
            continue;
        }
        for (i, h) in HORIZONS_MS.iter().enumerate() {
            let th = t + h / 1000.0;
            let Some(p) = f.predict(th) else { continue };
            let e = ((p * coil) - (traj.rest_from_head(th) * coil)).norm() * 1e3;
            let s = &mut sums[i];
            s.0 += e * e;
            s.1 = f64::max(s.1, e);
            s.2 += 1;
        }
    }
    Ok(sums
        .iter()
        .map(|(sq, max, n)| ((sq / *n as f64).sqrt(), *max))
        .collect())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut motions = vec![
        ("nods 89 mm/s, 37°/s", HeadMotion::Nods(Nods::default())),
        (
            "random (demo default)",
            HeadMotion::Random(RandomMotion::default()),
        ),
    ];
    if let Some(path) = std::env::args().nth(1) {
        let m = HeadMotion::from_file(&path, std::path::Path::new("."))?;
        motions.push(("replayed trace", m));
    }
    let variants: Vec<(String, PredictorConfig)> = match std::env::var("VARIANTS") {
        Ok(v) => v
            .split(';')
            .map(|spec| Ok((spec.to_string(), toml::from_str(&spec.replace(',', "\n"))?)))
            .collect::<Result<_, toml::de::Error>>()?,
        Err(_) => vec![
            (
                "before issue 16: cv".into(),
                PredictorConfig::constant_velocity(),
            ),
            (
                "ca, IMM, the filter alone".into(),
                PredictorConfig {
                    learned: false,
                    ..PredictorConfig::default()
                },
            ),
            (
                "ca, IMM and learned (default)".into(),
                PredictorConfig::default(),
            ),
        ],
    };
    let noise_scale: f64 = match std::env::var("NOISE") {
        Ok(v) => v.parse()?,
        Err(_) => 1.0,
    };
    print!("| motion | filter |");
    for h in HORIZONS_MS {
        print!(" {h:.0} ms RMS / max |");
    }
    println!();
    println!("|---|---|{}", "---|".repeat(HORIZONS_MS.len()));
    for (name, m) in &motions {
        for (label, cfg) in variants.iter().map(|(l, c)| (l.as_str(), *c)) {
            print!("| {name} | {label} |");
            for (rms, max) in study(m, cfg, 1, noise_scale)? {
                print!(" {rms:.2} / {max:.2} |");
            }
            println!();
        }
    }
    println!(
        "\nerrors in mm at the coil's centre (113 mm from the head marker); 60 Hz, {:.2} mm, {:.1} mrad, seed 1",
        0.1 * noise_scale,
        noise_scale
    );
    Ok(())
}
