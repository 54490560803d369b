//! The run report written as a whole: report.json, report.md and the plots, plus a VTK series.

use std::path::PathBuf;

use pairsum::report::{self, Curve, GroupBytes, History, PointField, ResultRow, RunReport, Series};

fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pairsum-tests-report-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn sample_report() -> RunReport {
    RunReport {
        case: "taylor_green".into(),
        backend: "cpu".into(),
        precision: "f64".into(),
        particles: 4096,
        steps: 200,
        wall_s: 2.5,
        particle_steps_per_s: 4096.0 * 200.0 / 2.5,
        results: vec![
            ResultRow::new("decay rate", "1/s", 0.079, Some(0.08)).with_source("analytic"),
            ResultRow::new("max |v|", "m/s", 1.0, None),
        ],
        bytes_per_particle: vec![GroupBytes { group: "fluid".into(), bytes: 112 }],
        histories: vec![
            History {
                name: "kinetic energy".into(),
                x_label: "t [s]".into(),
                y_label: "E_k [J]".into(),
                series: vec![
                    Curve::new("sph", (0..20).map(|i| (i as f64 * 0.05, (-0.16 * i as f64 * 0.05).exp())).collect()),
                    Curve::new("exact", (0..20).map(|i| (i as f64 * 0.05, (-0.16 * i as f64 * 0.05).exp())).collect()),
                ],
                reference: None,
                log_log: false,
            },
            History {
                name: "mass".into(),
                x_label: "t [s]".into(),
                y_label: "m [kg]".into(),
                series: vec![Curve::new("total", vec![(0.0, 1.0), (1.0, 1.0)])],
                reference: Some(1.0),
                log_log: false,
            },
        ],
        notes: vec!["decay rate fitted on t in [0.1, 1]".into()],
        resolution: "64 x 64".into(),
        dx: 1.0 / 64.0,
        end_time: 1.0,
        tables: vec![],
    }
}

#[test]
fn report_json_and_markdown() {
    let dir = tmpdir("write");
    let r = sample_report();
    report::write(&dir, &r).unwrap();

    let text = std::fs::read_to_string(dir.join("report.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    for key in ["case", "backend", "precision", "particles", "steps", "wall_s", "particle_steps_per_s", "results"] {
        assert!(v.get(key).is_some(), "report.json lacks `{key}`");
    }
    assert_eq!(v["case"], "taylor_green");
    assert_eq!(v["particles"], 4096);
    let row = &v["results"][0];
    for key in ["quantity", "unit", "value", "reference", "rel_error"] {
        assert!(row.get(key).is_some(), "result row lacks `{key}`");
    }
    assert!((row["rel_error"].as_f64().unwrap() - (-0.0125)).abs() < 1e-12);
    assert!(v["results"][1]["reference"].is_null() && v["results"][1]["rel_error"].is_null());
    let back: RunReport = serde_json::from_str(&text).unwrap();
    assert_eq!(back, r);

    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("# Run report: taylor_green"));
    assert!(md.contains("| decay rate | 1/s | 0.08 | 0.079 | -1.25 % | analytic |"), "{md}");
    for text in ["4096", "200", "2.5 s", "327680", "cpu", "f64", "64 x 64", "| fluid | 112 |", "fitted on t"] {
        assert!(md.contains(text), "report.md lacks {text:?}:\n{md}");
    }
    assert!(md.contains("![kinetic energy](kinetic_energy.svg)"));
    assert!(md.contains("![mass](mass.svg)"));
    let svg = std::fs::read_to_string(dir.join("kinetic_energy.svg")).unwrap();
    assert!(svg.contains("sph") && svg.contains("exact"));
    assert!(std::fs::metadata(dir.join("mass.svg")).unwrap().len() > 0);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn vtk_series_lists_files() {
    let dir = tmpdir("series");
    let mut s = Series::new(&dir, "particles").unwrap();
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    for k in 0..3 {
        let rho = PointField::scalar("rho", vec![1000.0 + k as f64, 1000.0]);
        s.add(k as f64 * 0.1, &pos, &[rho]).unwrap();
    }
    let pvd = std::fs::read_to_string(dir.join("particles.pvd")).unwrap();
    for k in 0..3 {
        let name = format!("particles_{k:06}.vtu");
        assert!(pvd.contains(&format!("file=\"{name}\"")), "{pvd}");
        assert!(dir.join(&name).exists());
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `pairsum uncertainty` with `args` on 5 − 0.3 Δx^1.3 at the `spacings`: its standard output,
/// after asserting that it succeeded.
fn uncertainty_of_a_power_law(spacings: &[f64], args: &[&str]) -> String {
    let levels: Vec<String> = spacings.iter().map(|h| format!("{h}={}", 5.0 - 0.3 * h.powf(1.3))).collect();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_pairsum"))
        .arg("uncertainty")
        .args(&levels)
        .args(args)
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{text}{}", String::from_utf8_lossy(&out.stderr));
    text
}

#[test]
fn the_uncertainty_command_prints_a_power_laws_order_limit_and_u_and_rejects_three_levels_or_a_bad_level() {
    use std::process::Command;
    // 5 − 0.3 Δx^1.3 at four spacings: order 1.3, f0 5, U = 1.25 × 0.3 × 0.5^1.3 = 0.1523…
    let text = uncertainty_of_a_power_law(&[2.0, 1.5, 1.0, 0.5], &["--reference", "4.9"]);
    assert!(text.contains("observed order p (least squares, all 4 levels): 1.30\n"), "{text}");
    let u: f64 = text.lines().find_map(|l| l.split(" ± ").nth(1)).expect("finest ± U").trim().parse().expect("U");
    assert!((u - 1.25 * 0.3 * 0.5f64.powf(1.3)).abs() < 1e-5, "{u}");
    assert!(text.contains("the reference 4.9 lies within it"), "4.9 is 0.023 from the finest value: {text}");
    let three = Command::new(env!("CARGO_BIN_EXE_pairsum")).args(["uncertainty", "3=1", "2=2", "1=2.5"]).output();
    let three = three.expect("runs");
    assert_eq!(three.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&three.stderr).contains("it needs four levels or more"));
    let bad = Command::new(env!("CARGO_BIN_EXE_pairsum")).args(["uncertainty", "1=2", "0.5:3"]).output().expect("runs");
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("`0.5:3` is not SPACING=VALUE"));
}

#[test]
fn the_uncertainty_commands_json_gives_a_power_laws_order_limit_u_and_the_references_distance_beyond_it() {
    // 5 − 0.3 Δx^1.3 at four spacings, as above; the reference 5.5 lies 0.5 − U beyond 4.9 … ± U
    let text = uncertainty_of_a_power_law(&[2.0, 1.5, 1.0, 0.5], &["--reference", "5.5", "--json"]);
    let json: serde_json::Value = serde_json::from_str(&text).expect("one JSON object");
    let number = |key: &str| json[key].as_f64().unwrap_or_else(|| panic!("{key} in {text}"));
    let finest = 5.0 - 0.3 * 0.5f64.powf(1.3);
    let u = 1.25 * 0.3 * 0.5f64.powf(1.3);
    assert!((number("order") - 1.3).abs() < 1e-3, "{text}");
    assert_eq!(json["order_text"], "1.30");
    assert!((number("f0") - 5.0).abs() < 1e-6, "{text}");
    assert!((number("finest_value") - finest).abs() < 1e-12 && number("finest_spacing") == 0.5, "{text}");
    assert!((number("u") - u).abs() < 1e-5, "{text}");
    assert!((number("beyond") - (5.5 - finest - u)).abs() < 1e-5, "{text}");
    assert_eq!(json["levels"], 4);
    assert!(
        json["order_without_one"].is_null() && json["order_without_one_text"].is_null(),
        "four levels: no order leaving one out: {text}"
    );
}

#[test]
fn the_uncertainty_commands_json_gives_five_levels_of_a_power_law_the_same_order_leaving_out_any_one() {
    // 5 − 0.3 Δx^1.3 at five spacings: every fit leaving out one level is exact, order 1.3
    let text = uncertainty_of_a_power_law(&[2.0, 1.5, 1.0, 0.75, 0.5], &["--json"]);
    let json: serde_json::Value = serde_json::from_str(&text).expect("one JSON object");
    let range = json["order_without_one"].as_array().unwrap_or_else(|| panic!("a range in {text}"));
    for p in range {
        assert!((p.as_f64().expect("a number") - 1.3).abs() < 1e-3, "{text}");
    }
    assert_eq!(json["order_without_one_text"], "1.30–1.30", "{text}");
    assert_eq!(json["levels"], 5);
}

/// `pairsum uncertainty` with each level's standard error (SPACING=VALUE±SE): 228 − 8 Δx at six
/// spacings with a standard error of 0.02 keeps the order 1 and f0 228 under the noise, with
/// every step resolved; one level without a standard error, or a negative one, is refused.
#[test]
fn the_uncertainty_command_with_standard_errors_gives_the_order_and_f0_range_under_the_noise() {
    let levels: Vec<String> =
        [1.0, 0.8, 2.0 / 3.0, 0.5, 0.4, 1.0 / 3.0].iter().map(|h| format!("{h}={}±0.02", 228.0 - 8.0 * h)).collect();
    let run = |levels: &[String], more: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_pairsum"))
            .arg("uncertainty")
            .args(levels)
            .args(more)
            .output();
        let out = out.expect("runs");
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, text, err) = run(&levels, &["--json"]);
    assert_eq!(code, Some(0), "{err}");
    let json: serde_json::Value = serde_json::from_str(&text).expect("one JSON object");
    let noise = &json["under_noise"];
    let pair = |k: &str| {
        let a = noise[k].as_array().unwrap_or_else(|| panic!("{k} in {text}"));
        (a[0].as_f64().expect("a number"), a[1].as_f64().expect("a number"))
    };
    let ((p0, p1), (f0, f1)) = (pair("order"), pair("f0"));
    assert!(p0 > 0.9 && p1 < 1.1, "{text}");
    assert!(f0 < 228.0 && f1 > 228.0 && f1 - f0 < 0.5, "{text}");
    assert_eq!((noise["resolved_steps"].as_u64(), noise["steps"].as_u64()), (Some(5), Some(5)), "{text}");
    assert!(noise["constant_fits"].as_f64().is_some_and(|p| p < 1e-10), "a trend of 8 per unit against 0.02: {text}");
    let first = noise["first_order_f0"].as_array().unwrap_or_else(|| panic!("first_order_f0 in {text}"));
    assert!((first[0].as_f64().expect("f0") - 228.0).abs() < 1e-9, "the line is exact: {text}");
    let (code, text, _) = run(&levels.iter().map(|l| l.replace('±', "+-")).collect::<Vec<_>>(), &[]);
    assert_eq!(code, Some(0));
    assert!(text.contains("larger than twice their combined standard error: 5 of 5"), "{text}");
    let mut some = levels.clone();
    some[2] = some[2].split('±').next().unwrap().to_string();
    let (code, _, err) = run(&some, &[]);
    assert_eq!(code, Some(1));
    assert!(err.contains("give every level a standard error"), "{err}");
    let mut negative = levels.clone();
    negative[0] = negative[0].replace("±0.02", "±-0.02");
    let (code, _, err) = run(&negative, &[]);
    assert_eq!(code, Some(1));
    assert!(err.contains("negative"), "{err}");
}
