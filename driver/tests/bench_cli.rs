//! `guidebake bench --quick` runs end to end on the demo room and writes well-formed
//! outputs: CSVs with the documented columns and finite values, a JSON summary with every
//! method's curve and the overhead of every guiding mode, the Markdown table, and charts that
//! are valid PNG and SVG. Bad options fail with a message naming the option, and write nothing.

use std::path::Path;

use guidebake::bench::method::Method;
use guidebake::bench::report::{OVERHEAD_COLUMNS, RUN_COLUMNS};

mod cli;

/// Parses a CSV without quoting (the harness writes none) into its header and rows.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .expect("a header line")
        .split(',')
        .map(str::to_owned)
        .collect();
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(
            row.len(),
            header.len(),
            "{} row {i}: {row:?}",
            path.display()
        );
    }
    (header, rows)
}

fn column<'a>(header: &[String], rows: &'a [Vec<String>], name: &str) -> Vec<&'a str> {
    let i = header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("column {name}"));
    rows.iter().map(|r| r[i].as_str()).collect()
}

fn finite_column(header: &[String], rows: &[Vec<String>], name: &str) -> Vec<f64> {
    column(header, rows, name)
        .into_iter()
        .map(|v| {
            let x: f64 = v
                .parse()
                .unwrap_or_else(|_| panic!("{name}: '{v}' is a number"));
            assert!(x.is_finite(), "{name}: {x} is finite");
            x
        })
        .collect()
}

/// Every number in the JSON is finite (serde writes NaN as null; nulls are only allowed where
/// a value may be unmeasurable, which the checks below name).
fn numbers(v: &serde_json::Value, out: &mut Vec<f64>) {
    match v {
        serde_json::Value::Number(n) => out.push(n.as_f64().expect("a number")),
        serde_json::Value::Array(a) => a.iter().for_each(|x| numbers(x, out)),
        serde_json::Value::Object(o) => o.values().for_each(|x| numbers(x, out)),
        _ => {}
    }
}

fn check_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
        "{} is a PNG",
        path.display()
    );
    let image = image::load_from_memory(&bytes)
        .expect("the PNG decodes")
        .to_rgb8();
    assert!(image.width() >= 400 && image.height() >= 300);
    // A chart, not a blank page: white background with lines and text in other colours.
    let inked = image.pixels().filter(|p| p.0 != [255, 255, 255]).count();
    let share = inked as f64 / f64::from(image.width() * image.height());
    assert!(
        (0.01..0.6).contains(&share),
        "{}: {share} of pixels inked",
        path.display()
    );
}

fn check_svg(path: &Path) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let trimmed = text.trim();
    assert!(
        trimmed.starts_with("<svg") || trimmed.starts_with("<?xml"),
        "{}",
        path.display()
    );
    assert!(trimmed.ends_with("</svg>"), "{} is closed", path.display());
    assert!(text.contains("<text"), "{} has labels", path.display());
    assert!(
        text.contains("<polyline") || text.contains("<rect"),
        "{} has marks",
        path.display()
    );
}

#[test]
fn quick_bench_writes_well_formed_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let cache = dir.path().join("cache");
    let status = cli::command()
        .args(["bench", "--quick", "--threads", "2", "-o"])
        .arg(&out)
        .arg("--cache")
        .arg(&cache)
        .status()
        .expect("the binary runs");
    assert!(status.success(), "guidebake bench --quick failed");

    let methods = Method::all();
    let (header, rows) = read_csv(&out.join("runs.csv"));
    assert_eq!(header, RUN_COLUMNS);
    assert_eq!(
        rows.len(),
        methods.len() * 2,
        "every method at 2 sample counts, one seed"
    );
    for name in &RUN_COLUMNS[5..] {
        finite_column(&header, &rows, name);
    }
    for m in &methods {
        let label = m.label();
        assert_eq!(
            column(&header, &rows, "method")
                .iter()
                .filter(|l| **l == label)
                .count(),
            2,
            "{label}"
        );
    }
    let rmse = finite_column(&header, &rows, "rmse");
    assert!(
        rmse.iter().all(|e| *e > 0.0),
        "no run equals the reference bit for bit"
    );
    let wall = finite_column(&header, &rows, "wall_s");
    assert!(wall.iter().all(|t| *t > 0.0));
    let rays = finite_column(&header, &rows, "gather_rays");
    let spp = finite_column(&header, &rows, "spp");
    let texels = finite_column(&header, &rows, "texels");
    for ((r, s), t) in rays.iter().zip(&spp).zip(&texels) {
        assert_eq!(*r, s * t, "spp gather rays per compared texel");
    }

    let (oh, orows) = read_csv(&out.join("overhead.csv"));
    assert_eq!(oh, OVERHEAD_COLUMNS);
    for name in &OVERHEAD_COLUMNS[2..] {
        finite_column(&oh, &orows, name);
    }
    for mode in ["off", "naive", "coherent"] {
        assert_eq!(
            column(&oh, &orows, "guiding")
                .iter()
                .filter(|g| **g == mode)
                .count(),
            3,
            "3 repeats of {mode}"
        );
    }

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let mut all = Vec::new();
    numbers(&summary, &mut all);
    assert!(all.iter().all(|x| x.is_finite()));
    assert_eq!(summary["curves"].as_array().unwrap().len(), methods.len());
    for curve in summary["curves"].as_array().unwrap() {
        assert_eq!(curve["points"].as_array().unwrap().len(), 2);
    }
    let modes = summary["overhead"]["modes"].as_array().unwrap();
    assert_eq!(modes[0]["guiding"], "off");
    assert!((modes[0]["gather_ratio"].as_f64().unwrap() - 1.0).abs() < 1e-12);
    for m in modes {
        let ratio = m["gather_ratio"].as_f64().expect("a measured ratio");
        assert!(ratio > 0.0);
    }
    assert!(summary["equal_time"]["budget_s"].as_f64().unwrap() > 0.0);
    assert!(
        summary["equal_time"]["baseline_rmse_at_4x"]["value"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    assert_eq!(summary["targets"].as_array().unwrap().len(), 3);
    assert_eq!(summary["reference"]["cached"], false);
    // The defaults: series bakes against a path reference, series overhead runs.
    assert_eq!(summary["ladder"]["transport"], "series");
    assert_eq!(summary["overhead"]["transport"], "series");
    assert!(
        summary["reference"]["settings"]
            .as_str()
            .is_some_and(|s| s.contains("transport: Path")),
        "{}",
        summary["reference"]["settings"]
    );
    assert!(summary["texels"].as_u64().unwrap() > 100);

    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(table.contains("| coherent/texel/rho |"));
    assert!(table.contains("| off |"), "the overhead table");

    for chart in ["rmse_vs_time", "relmse_vs_time", "overhead"] {
        check_png(&out.join(format!("{chart}.png")));
        check_svg(&out.join(format!("{chart}.svg")));
    }
    assert!(!out.join(".runs").exists(), "the scratch bakes are removed");
    let cached: Vec<String> = std::fs::read_dir(&cache)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    for ext in [".exr", ".json"] {
        assert!(
            cached
                .iter()
                .any(|f| f.starts_with("ref-") && f.ends_with(ext)),
            "the reference's {ext} is cached: {cached:?}"
        );
    }
}

#[test]
fn bad_options_name_the_option_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let run = |args: &[&str]| {
        let o = cli::command()
            .arg("bench")
            .args(args)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        assert!(!o.status.success(), "{args:?} fails");
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    assert!(run(&["--spp", "64"]).contains("--spp"));
    // 8× the largest --spp: the reference must have 16×.
    assert!(run(&["--spp", "32,64", "--ref-spp", "512"]).contains("--ref-spp"));
    assert!(run(&["--spp", "4,64"]).contains("--spp 4"));
    let missing = dir.path().join("no-such-scene.glb");
    let message = run(&[missing.to_str().unwrap()]);
    assert!(message.contains("no-such-scene.glb"), "{message}");
    assert!(!out.exists(), "nothing is written for bad options");
}

/// `--reference-noise` bakes the reference's twin beside it (cached too) and reports the
/// reference's noise, which is a part of every run's error and so less than any of them.
#[test]
fn the_reference_noise_comes_from_a_cached_twin() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let bench = |out: &Path| {
        let status = cli::command()
            .args(["bench", "--quick", "--threads", "2", "--repeats", "0"])
            .args(["--methods", "off/average/-", "--reference-noise", "-o"])
            .arg(out)
            .arg("--cache")
            .arg(&cache)
            .status()
            .expect("the binary runs");
        assert!(status.success(), "guidebake bench --reference-noise failed");
        let text = std::fs::read_to_string(out.join("summary.json")).unwrap();
        serde_json::from_str::<serde_json::Value>(&text).unwrap()
    };
    let out = dir.path().join("first");
    let summary = bench(&out);
    let noise = &summary["reference_noise"];
    let (rel, mse) = (
        noise["rel_mse"].as_f64().unwrap(),
        noise["mse"].as_f64().unwrap(),
    );
    assert!(
        rel > 0.0 && rel.is_finite() && mse > 0.0 && mse.is_finite(),
        "{noise}"
    );
    let (header, rows) = read_csv(&out.join("runs.csv"));
    for run in finite_column(&header, &rows, "rel_mse") {
        assert!(
            rel < run,
            "the reference's noise {rel} is a part of a run's error {run}"
        );
    }
    for rmse in finite_column(&header, &rows, "rmse") {
        assert!(mse < rmse * rmse, "{mse} against {}", rmse * rmse);
    }
    assert_eq!(noise["twin"]["cached"], false);
    assert_ne!(noise["twin"]["key"], summary["reference"]["key"]);
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(
        table.contains("the mean of the bake above and its twin"),
        "{table}"
    );
    let jsons = std::fs::read_dir(&cache)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "json")
        })
        .count();
    assert_eq!(jsons, 2, "the reference and its twin are cached");

    let again = bench(&dir.path().join("second"));
    assert_eq!(again["reference_noise"]["twin"]["cached"], true);
    assert_eq!(again["reference_noise"]["rel_mse"], noise["rel_mse"]);
}
