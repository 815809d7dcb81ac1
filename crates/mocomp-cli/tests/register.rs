#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! `mocomp register` and `register check` against pyigtl 0.3.4 (required) as the tracker's
//! server, streaming a scripted session on FreeSurfer's fsaverage head (MNE's, required): the
//! head marker nodding, the pointer touching the nasion and both preauricular points in turn
//! (each brought in from the air, held, then taken away), then swept over the scalp. Noise model
//! (seeded): each touch lands 0.7 mm per axis along the skin off the landmark, the tracker adds
//! 0.2 mm per axis to every tip, and a tip presses up to 1 mm into the skin. The image is placed
//! in the marker's frame by a transform the configuration does not know; registration must find
//! it. `register --simulate` runs the same procedure in the built-in world, against its truth.

mod common;
use common::session::{Session, browse};
use common::{
    assert_success, fsaverage_config, mocomp, pose_json, pose_toml, pose6, pyigtl_streaming, rows4,
};
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use mocomp_head::{HeadShape, Mesh, MeshHead, repair};
use mocomp_testkit::{PythonPeer, SplitMix64, TempDir};
use serde_json::{Value, json};

const TIP_MM: [f64; 3] = [2.5, -4.0, 161.0];

/// The truth: the image's frame in the head marker's.
fn marker_from_image() -> Isometry3<f64> {
    pose6(&[0.02, -0.05, 0.08, 0.2, -0.3, 0.5])
}

/// A truth nearer the identity, for the simulated world, whose robot must reach F3 on the head
/// the marker's frame holds.
fn marker_from_image_near() -> Isometry3<f64> {
    pose6(&[0.004, -0.006, 0.01, 0.04, -0.03, 0.06])
}

/// The head marker in the tracker's view at frame k: nodding 3° at 0.5 Hz, 200 frames a second.
fn tracker_from_head(k: usize) -> Isometry3<f64> {
    let nod = 3f64.to_radians() * (std::f64::consts::TAU * 0.5 * k as f64 / 200.0).sin();
    Isometry3::from_parts(
        Translation3::new(0.1, 0.05, 1.0),
        UnitQuaternion::from_euler_angles(nod, 0.4, -0.2),
    )
}

/// A pose (m) as the rows of its 4×4, translation in mm.
fn rows(m: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let mut h = m.to_homogeneous();
    for r in 0..3 {
        h[(r, 3)] *= 1000.0;
    }
    rows4(&h)
}

/// One frame: the head marker and the pointer whose tip is at `tip_in_head`.
fn frame(rng: &mut SplitMix64, k: usize, tip_in_head: &Point3<f64>) -> Value {
    let head = tracker_from_head(k);
    let tip_tracker =
        head * tip_in_head + Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * 0.2e-3;
    let r = UnitQuaternion::from_euler_angles(0.3, -0.2, 0.1 + 0.001 * k as f64);
    let t = tip_tracker.coords - r * (Vector3::from(TIP_MM) / 1000.0);
    let pointer = Isometry3::from_parts(Translation3::from(t), r);
    json!({"HeadToTracker": rows(&head), "StylusToTracker": rows(&pointer)})
}

fn fsaverage() -> MeshHead {
    let (v, t) = mocomp_testkit::anatomy::fsaverage_head();
    let raw = Mesh {
        vertices: v.iter().map(|p| Point3::from(*p)).collect(),
        triangles: t,
    };
    MeshHead::new(repair(raw, "fsaverage").unwrap().0, "fsaverage").unwrap()
}

/// The landmarks touched in turn (image frame), then `sweep` scalp points: the frames.
fn session(
    rng: &mut SplitMix64,
    to_head: &Isometry3<f64>,
    touch: &[Point3<f64>],
    sweep: usize,
) -> Vec<Value> {
    let mut frames = Vec::new();
    let out = Vector3::new(0.0, 0.0, 0.04);
    let scalp = fsaverage();
    for p in touch {
        // On the skin, 0.7 mm per axis along it off the landmark, pressed in up to 1 mm.
        let s = scalp.nearest(p);
        let n = s.normal.into_inner();
        let g = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * 0.7e-3;
        let on = scalp.nearest(&(s.point + (g - n * g.dot(&n))));
        let aimed = on.point - on.normal.into_inner() * (1e-3 * rng.next_f64());
        for s in 0..20 {
            let q = aimed + out * (1.0 - s as f64 / 20.0);
            frames.push(frame(rng, frames.len(), &(to_head * q)));
        }
        for _ in 0..40 {
            frames.push(frame(rng, frames.len(), &(to_head * aimed)));
        }
        for s in 0..20 {
            let q = aimed + out * (s as f64 / 20.0);
            frames.push(frame(rng, frames.len(), &(to_head * q)));
        }
    }
    if sweep > 0 {
        let up: Vec<Point3<f64>> = scalp
            .vertices()
            .iter()
            .filter(|p| p.z > -0.03)
            .copied()
            .collect();
        for _ in 0..sweep {
            let p = up[(rng.next_u64() % up.len() as u64) as usize];
            let s = scalp.nearest(&p);
            let pressed = s.point - s.normal.into_inner() * (1e-3 * rng.next_f64());
            frames.push(frame(rng, frames.len(), &(to_head * pressed)));
        }
    }
    frames
}

fn stream(frames: Vec<Value>) -> (PythonPeer, String) {
    pyigtl_streaming(frames, 200.0)
}

fn write_setup(
    dir: &TempDir,
) -> (
    String,
    String,
    std::collections::BTreeMap<String, Point3<f64>>,
) {
    let (config, points) = fsaverage_config(dir, "");
    let pointer = dir.path("pointer.toml");
    std::fs::write(
        &pointer,
        format!(
            "[pointer]\ndevice = \"StylusToTracker\"\ntip_in_marker_mm = {TIP_MM:?}\n\
             pivot_in_tracker_mm = [0.0, 0.0, 0.0]\nrms_mm = 0.4\nmax_mm = 0.9\nkept = 200\n\
             rejected = 0\ninvalid = 0\nspread_deg = 40.0\ncalibrated_at = \"now\"\n"
        ),
    )
    .unwrap();
    (config, pointer, points)
}

/// `mocomp register [sub] --config C --pointer P --igtl A` and `extra`.
fn register(
    sub: &[&str],
    config: &str,
    pointer: &str,
    addr: &str,
    extra: &[&str],
) -> std::process::Output {
    let mut args = vec!["register"];
    args.extend(sub);
    args.extend(["--config", config, "--pointer", pointer, "--igtl", addr]);
    args.extend(extra);
    mocomp(&args)
}

#[test]
fn a_session_streamed_by_pyigtl_registers_the_head_and_a_moved_marker_is_caught() {
    let dir = TempDir::new("register-cli");
    let (config, pointer, points) = write_setup(&dir);
    let mut rng = SplitMix64(3210);
    let touch = [points["nasion"], points["lpa"], points["rpa"]];
    let (_py, addr) = stream(session(&mut rng, &marker_from_image(), &touch, 150));
    let reg = dir.path("registration.toml");
    let out = register(
        &[],
        &config,
        &pointer,
        &addr,
        &["--out", &reg, "--json", "--sweep-points", "100"],
    );
    assert_success(&out);
    eprintln!("{}", String::from_utf8_lossy(&out.stderr));
    let got: Value = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!("{got}");
    let found = pose_json(&got["head_from_image"]);
    let truth = marker_from_image();
    for (name, at) in [
        ("F3", points["F3"]),
        ("deep", Point3::new(-0.03, -0.02, 0.03)),
    ] {
        let e = (found * at - truth * at).norm();
        eprintln!("registration error at {name}: {:.2} mm", e * 1e3);
        assert!(e < 2.5e-3, "{name}: {:.2} mm", e * 1e3);
    }
    let fre = got["fre_mm"].as_f64().unwrap();
    assert!(fre > 0.1 && fre < 3.0, "FRE {fre}");
    let rms = got["surface_rms_mm"].as_f64().unwrap();
    assert!(rms > 0.1 && rms < 0.8, "surface RMS {rms}");
    // At least the sweep's fewest; it ends early once the bound at the goal is small enough.
    assert!(got["surface_points"].as_u64().unwrap() >= 40, "{got}");
    // The 95 % bound at the configuration's goal (the crown): above the errors measured above,
    // as a bound is.
    let tre = got["tre_mm"]["[goal]"].as_f64().unwrap();
    assert!((0.5..4.0).contains(&tre), "error bound {tre}");
    assert_eq!(got["usable"], true, "{got}");
    assert_eq!(got["file"], reg.as_str(), "{got}");

    // The registration in use: touching the nasion again finds it where it was.
    let text = std::fs::read_to_string(&config).unwrap();
    let registered = dir.path("registered.toml");
    std::fs::write(
        &registered,
        text.replace("[head]\n", "[head]\nregistration = \"registration.toml\"\n"),
    )
    .unwrap();
    let (_py, addr) = stream(session(
        &mut rng,
        &marker_from_image(),
        &[points["nasion"]],
        0,
    ));
    let out = register(&["check"], &registered, &pointer, &addr, &["--json"]);
    assert_success(&out);
    let held: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(held["moved"], false, "{held}");
    assert!(held["moved_mm"].as_f64().unwrap() < held["limit_mm"].as_f64().unwrap());

    // The marker slipped 6 mm on the head: the nasion is touched 6 mm from where it was.
    let slipped = [points["nasion"] + Vector3::new(0.0, 0.0, 0.006)];
    let (_py, addr) = stream(session(&mut rng, &marker_from_image(), &slipped, 0));
    let out = register(&["check"], &registered, &pointer, &addr, &["--json"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("moved on the head"), "{err}");
    let moved: Value = serde_json::from_slice(&out.stdout).unwrap();
    let mm = moved["moved_mm"].as_f64().unwrap();
    assert!((4.0..8.0).contains(&mm), "{moved}");
}

/// The run configuration: the example's simulated cell, the head turned so that its F3 faces
/// the coil robot's workspace, `[head]` the registered scan, the session starting on `dlpfc`.
fn run_config(dir: &TempDir, nav: &str, max_tre_mm: f64) -> String {
    let example =
        std::fs::read_to_string(mocomp_testkit::workspace_root().join("examples/run-sim.toml"))
            .unwrap();
    let head = std::fs::read_to_string(nav).unwrap();
    let ellipsoid = "[head]                         # an ellipsoid in the head marker's frame\n\
                     head_from_ellipsoid = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\nradii_m = [0.075, 0.095, 0.11]\n";
    let ellipsoid_marks = example
        .split("[head.landmarks]")
        .nth(1)
        .and_then(|rest| rest.split("\n\n").next())
        .map(|block| format!("[head.landmarks]{block}\n"))
        .expect("the example's landmarks on its ellipsoid");
    assert!(example.contains(ellipsoid), "the example's [head] changed");
    let at_rest = "base_from_head = [0.30, -0.12, -0.02, 0.0, 0.0, 0.3]";
    assert!(example.contains(at_rest), "the example's head changed");
    // Its own loopback addresses for the simulated robots, as every test has.
    let text = example
        .replace("host = \"127.0.0.2\"", "host = \"127.0.0.130\"")
        .replace(ellipsoid, "")
        .replace(&ellipsoid_marks, "")
        .replace(
            at_rest,
            "base_from_head = [0.30, -0.12, -0.02, 0.0, 0.0, 2.0]",
        )
        + &head.replace(
            "[head]\n",
            &format!("[head]\nregistration = \"registration.toml\"\nmax_tre_mm = {max_tre_mm}\n"),
        )
        + "\n[session]\ntargets = \"targets.toml\"\ntarget = \"dlpfc\"\n";
    let path = dir.path(&format!("run-{max_tre_mm}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn registered_and_targeted_at_f3_the_loop_compensates_on_the_nodding_head_and_the_gate_opens() {
    let dir = TempDir::new("register-e2e");
    let (nav, pointer, points) = write_setup(&dir);
    let mut rng = SplitMix64(77);
    let touch = [points["nasion"], points["lpa"], points["rpa"]];
    let (_py, addr) = stream(session(&mut rng, &marker_from_image_near(), &touch, 150));
    let reg = dir.path("registration.toml");
    let out = register(
        &[],
        &nav,
        &pointer,
        &addr,
        &["--out", &reg, "--sweep-points", "100"],
    );
    assert_success(&out);
    let config = run_config(&dir, &nav, 3.0);
    let targets = dir.path("targets.toml");
    let out = mocomp(&[
        "targets", "--file", &targets, "add", "dlpfc", "--config", &config, "--eeg", "F3",
    ]);
    assert_success(&out);

    // The loop on the built-in simulated UR3e, the head nodding: the coil reaches F3, follows
    // it, and the on-target gate opens. 3D Slicer's side is pyigtl, a client of `--slicer`.
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_mocomp"))
        .args([
            "run",
            "--config",
            &config,
            "--seconds",
            "300",
            "--quiet",
            "--json",
            "--slicer",
            "127.0.0.1:0",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (lines_tx, lines_rx) = std::sync::mpsc::channel::<String>();
    let stderr = child.stderr.take().unwrap();
    let drain = std::thread::spawn(move || {
        use std::io::BufRead;
        let mut all = String::new();
        for line in std::io::BufReader::new(stderr)
            .lines()
            .map_while(Result::ok)
        {
            lines_tx.send(line.clone()).ok();
            all += &line;
            all.push('\n');
        }
        all
    });
    let port = loop {
        let line = lines_rx
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("mocomp run said where it serves Slicer");
        if let Some(rest) = line.split("3D Slicer: OpenIGTLink on ").nth(1) {
            let addr = rest.split_whitespace().next().unwrap();
            break addr.rsplit(':').next().unwrap().parse::<u16>().unwrap();
        }
    };
    let mut slicer = PythonPeer::start("pyigtl_peer.py", "pyigtl", "0.3.4");
    slicer.request(&json!({"op": "client", "port": port}));
    // A device's newest message, as soon as there is one. The run sends the coil only while
    // the head is tracked, and a starved machine (two suites and stress-ng on two cores) can
    // hold the run's logger or the peer back for seconds: only a run that never sends it, by
    // the test's deadline, fails.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(240);
    let newest = move |slicer: &mut PythonPeer, device: &str| loop {
        let m = slicer.request(&json!({"op": "wait", "device": device, "timeout": 5}));
        if m["found"] == true {
            return m;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "Slicer got no {device} by the test's deadline: {m}"
        );
    };
    let seen = |slicer: &mut PythonPeer, device: &str| {
        let m = newest(slicer, device);
        let v = &m["matrix"];
        Isometry3::from_parts(
            Translation3::new(
                v[0][3].as_f64().unwrap() / 1e3,
                v[1][3].as_f64().unwrap() / 1e3,
                v[2][3].as_f64().unwrap() / 1e3,
            ),
            UnitQuaternion::from_matrix(&mocomp_geom::nalgebra::Matrix3::from_fn(|r, c| {
                v[r][c].as_f64().unwrap()
            })),
        )
    };
    let apart = |a: &Isometry3<f64>, b: &Isometry3<f64>| {
        (
            (a.translation.vector - b.translation.vector).norm(),
            a.rotation.angle_to(&b.rotation),
        )
    };
    // Until the coil follows F3 (it reaches it about 6 s in), where Slicer sees it; then three
    // more seconds of the run's own time (the messages' stamps) for the gate, and the run is
    // ended as Ctrl-C would. The deadline only catches a run that never gets there.
    let started = std::time::Instant::now();
    let stamp =
        |slicer: &mut PythonPeer| newest(slicer, "CoilToImage")["timestamp"].as_f64().unwrap();
    let (coil, target, marker) = loop {
        let target = seen(&mut slicer, "TargetToImage");
        let coil = seen(&mut slicer, "CoilToImage");
        let (d, a) = apart(&coil, &target);
        if d < 3e-3 && a < 2f64.to_radians() {
            break (coil, target, seen(&mut slicer, "HeadMarkerToImage"));
        }
        assert!(
            started.elapsed().as_secs() < 180,
            "Slicer never saw the coil on F3's target: {d} m, {a} rad off"
        );
        std::thread::sleep(std::time::Duration::from_millis(200));
    };
    let on_target = stamp(&mut slicer);
    while stamp(&mut slicer) < on_target + 3.0 {
        assert!(
            started.elapsed().as_secs() < 240,
            "the run's time stood still"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let interrupted = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(interrupted.success());
    let output = child.wait_with_output().unwrap();
    let said = drain.join().unwrap();
    assert!(output.status.success(), "{said}");
    assert!(said.contains("error at dlpfc is within"), "{said}");
    let r: Value = serde_json::from_slice(&output.stdout).unwrap();
    eprintln!(
        "run on F3: tracking {:.0} %, deviation RMS {:.2} mm, p95 {:.2} mm, max {:.2} mm; gate openings {}",
        r["tracking_percent"].as_f64().unwrap(),
        r["deviation_rms_mm"].as_f64().unwrap(),
        r["deviation_p95_mm"].as_f64().unwrap(),
        r["deviation_max_mm"].as_f64().unwrap(),
        r["session"]["gate_openings"]
    );
    assert!(r["tracking_percent"].as_f64().unwrap() > 0.0, "{r}");
    assert!(r["deviation_rms_mm"].as_f64().unwrap() < 1.5, "{r}");
    assert!(r["session"]["gate_openings"].as_u64().unwrap() >= 1, "{r}");
    assert_eq!(r["protective_stops"], 0);
    // In Slicer: the target where F3's coil was placed on the image, the coil on it, the
    // marker where the registration put it.
    let f3 = f3_image_from_coil(&targets);
    let registered = registered_head_from_image(&reg);
    // The world here takes the registered head as the head: where the true F3 is, the coil
    // is off by the registration's own error there as well as by the loop's deviation.
    let f3_scalp = points["F3"];
    let registration_error = (registered * f3_scalp - marker_from_image_near() * f3_scalp).norm();
    eprintln!(
        "the registration's own error at F3: {:.2} mm (the coil's true error adds it to the deviation)",
        registration_error * 1e3
    );
    // Thirty seeded registrations put F3 within 2.2 mm at p95 (mocomp-nav's test); a wrong one is
    // centimetres off.
    assert!(registration_error < 3.5e-3, "{registration_error}");
    let (d, a) = apart(&target, &f3);
    assert!(
        d < 1e-5 && a < 1e-4,
        "TargetToImage {d} m, {a} rad from the target"
    );
    let (d, a) = apart(&coil, &target);
    eprintln!(
        "Slicer sees the coil {:.2} mm, {:.2}° from F3's target",
        d * 1e3,
        a.to_degrees()
    );
    assert!(
        d < 3e-3 && a < 2f64.to_radians(),
        "CoilToImage {d} m, {a} rad off"
    );
    let (d, a) = apart(&marker, &registered.inverse());
    assert!(d < 1e-5 && a < 1e-4, "HeadMarkerToImage {d} m, {a} rad off");

    // The same target in the paper's experiment, against the paper's pipeline.
    let demo_out = dir.path("demo");
    let out = mocomp(&[
        "demo",
        "--config",
        &config,
        "--target",
        "dlpfc",
        "--seconds",
        "12",
        "--motion",
        "nods",
        "--json",
        "--quiet",
        "--head-host",
        "127.0.0.131",
        "--out",
        &demo_out,
    ]);
    assert_success(&out);
    let d: Value = serde_json::from_slice(&out.stdout).unwrap();
    let by = |name: &str| {
        d["controllers"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["controller"] == name)
            .unwrap()
            .clone()
    };
    let (ours, paper) = (by("mocomp"), by("paper"));
    eprintln!(
        "demo on F3: mocomp d RMS {:.2} / max {:.2} mm, least clearance {:.1} mm; paper {:.2} / {:.2} mm",
        ours["d_rms"].as_f64().unwrap(),
        ours["d_max"].as_f64().unwrap(),
        ours["min_clearance_mm"].as_f64().unwrap(),
        paper["d_rms"].as_f64().unwrap(),
        paper["d_max"].as_f64().unwrap()
    );
    assert!(ours["d_rms"].as_f64().unwrap() < 1.5, "{ours}");
    assert!(ours["min_clearance_mm"].as_f64().unwrap() > 0.0, "{ours}");
    assert!(ours["d_rms"].as_f64().unwrap() * 3.0 < paper["d_rms"].as_f64().unwrap());

    // A threshold below the estimate: refused, named; overridden with a reason: it starts, and
    // the reason is in the registration file.
    let strict = run_config(&dir, &nav, 0.2);
    let out = mocomp(&["run", "--config", &strict, "--seconds", "1", "--quiet"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("head.max_tre_mm") && err.contains("--accept-registration"),
        "{err}"
    );
    let out = mocomp(&[
        "run",
        "--config",
        &strict,
        "--seconds",
        "1",
        "--quiet",
        "--accept-registration",
        "phantom session, accepted for the test",
    ]);
    assert_success(&out);
    let logged = std::fs::read_to_string(&reg).unwrap();
    assert!(
        logged.contains("[[override]]")
            && logged.contains("phantom session, accepted for the test"),
        "{logged}"
    );
}

fn f3_image_from_coil(targets: &str) -> Isometry3<f64> {
    let doc: toml::Value = toml::from_str(&std::fs::read_to_string(targets).unwrap()).unwrap();
    pose_toml(&doc["target"].as_array().unwrap()[0]["image_from_coil"])
}

fn registered_head_from_image(reg: &str) -> Isometry3<f64> {
    let doc: toml::Value = toml::from_str(&std::fs::read_to_string(reg).unwrap()).unwrap();
    pose_toml(&doc["registration"]["head_from_image"])
}

/// The operator's console on a rehearsal in the built-in world: the registration waits for the
/// page's Start, then shows each step, the landmarks, the sweep and the outcome with the true
/// error, in a real browser.
#[test]
fn the_registration_is_started_and_followed_in_the_console_in_a_real_browser() {
    let dir = TempDir::new("register-console");
    let config = rehearsal_config(
        &dir,
        "console.toml",
        "\n[registration]\nsweep_points = 80\n",
    );
    let pointer = true_pointer(&dir);
    let reg = dir.path("registration.toml");
    let s = Session::spawn(&[
        "register",
        "--simulate",
        "--config",
        &config,
        "--pointer",
        &pointer,
        "--seed",
        "5",
        "--out",
        &reg,
        "--dashboard",
        "127.0.0.1:0",
    ]);
    s.wait_status("the registration waiting for the go", |v| {
        v["navigation"]["state"] == "waiting"
    });
    let shots = dir.path("shots");
    let seen = browse(&s, &shots, "register");
    let landmarks: Vec<String> = seen["landmarks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_str().unwrap().to_string())
        .collect();
    assert!(
        landmarks[0].starts_with("nasion")
            && landmarks[1].starts_with("lpa")
            && landmarks[2].starts_with("rpa"),
        "{seen}"
    );
    let result = seen["result"].to_string();
    assert!(
        result.contains("registered: FRE")
            && result.contains("error at [goal]: within")
            && result.contains("true error at [goal]"),
        "{seen}"
    );
    let events = seen["events"].to_string();
    for step in [
        "touch the nasion",
        "take the pointer off the rpa",
        "sweep the pointer over the scalp",
    ] {
        assert!(events.contains(step), "{step}: {seen}");
    }
    assert_eq!(seen["mode"], "done", "{seen}");
    let (ok, printed) = s.finish();
    assert!(ok, "{printed}");
    assert!(printed.contains("registered: FRE"), "{printed}");
    assert!(std::path::Path::new(&reg).exists());
}

/// A pointer file with the simulated stylus's true tip.
fn true_pointer(dir: &TempDir) -> String {
    let pointer = dir.path("sim-pointer.toml");
    std::fs::write(
        &pointer,
        "[pointer]\ndevice = \"StylusToTracker\"\ntip_in_marker_mm = [2.5, -4.0, 161.0]\n\
         pivot_in_tracker_mm = [0.0, 0.0, 0.0]\nrms_mm = 0.3\nmax_mm = 0.8\nkept = 300\n\
         rejected = 0\ninvalid = 0\nspread_deg = 40.0\ncalibrated_at = \"now\"\n",
    )
    .unwrap();
    pointer
}

/// `examples/run-sim.toml` with its own loopback address, a brisk simulated operator and `extra`
/// appended (TOML tables).
fn rehearsal_config(dir: &TempDir, name: &str, extra: &str) -> String {
    let example =
        std::fs::read_to_string(mocomp_testkit::workspace_root().join("examples/run-sim.toml"))
            .unwrap();
    let text = example.replace("host = \"127.0.0.2\"", "host = \"127.0.0.132\"")
        + "\n[tracker.simulated.operator]\nspeed_mm_s = 80.0\nhold_s = 0.9\npivot_s = 5.0\n"
        + extra;
    let path = dir.path(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// The whole procedure rehearsed in the built-in world: the simulated operator pivots the
/// pointer (calibrated as `pointer calibrate` does), touches the ellipsoid head's landmarks and
/// sweeps it, over real OpenIGTLink from the simulated tracker, the head nodding. The result is
/// written, and its true error at the goal (the simulation's truth) lies within its bound (or
/// 2.5 mm). Held to a limit it cannot meet, the same registration is refused (exit 1), naming
/// the region to sweep, and nothing is written.
#[test]
fn a_registration_rehearsed_in_the_built_in_world_is_within_its_bound_or_refused() {
    let dir = TempDir::new("register-sim");
    let config = rehearsal_config(&dir, "sim.toml", "\n[registration]\nsweep_points = 120\n");
    let reg = dir.path("registration.toml");
    let out = mocomp(&[
        "register",
        "--simulate",
        "--config",
        &config,
        "--seed",
        "3",
        "--out",
        &reg,
        "--json",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_success(&out);
    assert!(err.contains("simulated pointer calibrated"), "{err}");
    assert!(
        err.contains("touch the nasion") && err.contains("sweep the"),
        "{err}"
    );
    let got: Value = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!("{got}");
    assert_eq!(got["usable"], true, "{got}");
    let truth = got["true_error_mm"]["[goal]"].as_f64().unwrap();
    let bound = got["tre_mm"]["[goal]"].as_f64().unwrap();
    assert!(truth < bound.max(2.5), "true {truth} mm, bound {bound} mm");
    assert!(std::path::Path::new(&reg).exists());
    let text = std::fs::read_to_string(&reg).unwrap();
    assert!(text.contains("covariance_mrad_mm"), "{text}");

    // Held to 0.3 mm at the goal: refused, the region named, nothing written.
    let strict = rehearsal_config(&dir, "strict.toml", "\n[registration]\nsweep_points = 60\n");
    let text = std::fs::read_to_string(&strict).unwrap().replace(
        "radii_m = [0.075, 0.095, 0.11]\n",
        "radii_m = [0.075, 0.095, 0.11]\nmax_tre_mm = 0.3\n",
    );
    std::fs::write(&strict, text).unwrap();
    let pointer = true_pointer(&dir);
    let refused_at = dir.path("refused.toml");
    let out = mocomp(&[
        "register",
        "--simulate",
        "--config",
        &strict,
        "--pointer",
        &pointer,
        "--out",
        &refused_at,
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    let said = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("refused, not written") && err.contains("sweep the"),
        "{err}"
    );
    assert!(
        said.contains("REFUSED") && said.contains("true error at [goal]"),
        "{said}"
    );
    assert!(!std::path::Path::new(&refused_at).exists());
}
