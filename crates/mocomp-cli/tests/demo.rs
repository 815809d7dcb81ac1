#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! `mocomp demo`, short: the experiment runs end to end from the command line, writes its CSV and
//! summary, and its JSON shows mocomp beating the paper's pipeline by the margins.

mod common;
use common::{assert_success, mocomp};
use mocomp_testkit::TempDir;

#[test]
fn the_demo_writes_its_report_and_mocomp_wins() {
    let dir = TempDir::new("mocomp-demo");
    let out_dir = dir.path("out");
    let out = mocomp(&[
        "demo",
        "--out",
        &out_dir,
        "--seconds",
        "10",
        "--json",
        "--quiet",
        "--coil-host",
        "127.0.0.55",
        "--head-host",
        "127.0.0.56",
    ]);
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = j["controllers"].as_array().unwrap();
    assert_eq!(rows[0]["controller"], "paper");
    assert_eq!(rows[1]["controller"], "mocomp");
    assert!(j["ratio_d_max"].as_f64().unwrap() >= 10.0, "{j}");
    assert!(rows[1]["translation_mm_rms"].as_f64().unwrap() < 0.5, "{j}");
    let csv = std::fs::read_to_string(format!("{out_dir}/demo.csv")).unwrap();
    // 10 s at 125 Hz, two controllers, and a header.
    assert_eq!(csv.lines().count(), 2 * 1250 + 1);
    // The figures: each a 1100×700 PNG and an SVG.
    for name in ["d", "errors", "head_speed", "latency", "events"] {
        let png = image::open(format!("{out_dir}/{name}.png"))
            .unwrap()
            .to_rgb8();
        assert_eq!(png.dimensions(), (1100, 700), "{name}.png");
        let svg = std::fs::read_to_string(format!("{out_dir}/{name}.svg")).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"),
            "{name}.svg"
        );
    }
    // d(t) draws every tick of both controllers, in their colours, twice (linear and log).
    let svg = std::fs::read_to_string(format!("{out_dir}/d.svg")).unwrap();
    for colour in ["#D62728", "#1F77B4"] {
        let lines: Vec<usize> = svg
            .split("<polyline")
            .skip(1)
            .filter(|p| p.contains(&format!("stroke=\"{colour}\"")))
            .map(|p| {
                let pts = p.split("points=\"").nth(1).unwrap();
                pts[..pts.find('"').unwrap()].split_whitespace().count()
            })
            .filter(|&n| n > 2)
            .collect();
        assert_eq!(lines, vec![1250, 1250], "{colour}");
    }
    let png = image::open(format!("{out_dir}/d.png")).unwrap().to_rgb8();
    for rgb in [[214, 39, 40], [31, 119, 180]] {
        let n = png.pixels().filter(|p| p.0 == rgb).count();
        assert!(n > 1000, "{rgb:?}: {n} pixels");
    }
    let md = std::fs::read_to_string(format!("{out_dir}/summary.md")).unwrap();
    assert!(
        md.contains("| mocomp |") && md.contains("| paper |"),
        "{md}"
    );
}
