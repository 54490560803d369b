//! The human-readable run report (`report.md`): the case, a table of results against their
//! references, the run's figures, state bytes per particle, notes, and one embedded SVG plot per
//! history (written next to the report).

use std::fmt::Write as _;
use std::io;
use std::path::Path;

use super::json::{History, RunReport};
use super::plot::plot_history;

/// The file name of a history's plot: its name with anything but ASCII letters, digits, `-` and
/// `_` replaced by `_`, plus `.svg` (`"Kinetic energy"` → `Kinetic_energy.svg`).
pub fn plot_file_name(h: &History) -> String {
    let stem: String =
        h.name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect();
    if stem.is_empty() {
        "plot.svg".into()
    } else {
        format!("{stem}.svg")
    }
}

/// Writes one SVG per history (named by [`plot_file_name`]) and `dir/report.md`. A plot that cannot
/// be drawn is replaced in the report by a line saying why, so the report is still written.
pub fn write_markdown(dir: &Path, report: &RunReport) -> io::Result<()> {
    let mut plot_errors = Vec::new();
    for h in &report.histories {
        plot_errors.push(plot_history(&dir.join(plot_file_name(h)), h).err());
    }
    crate::output_dir::write_atomic(&dir.join("report.md"), render_with(report, &plot_errors).as_bytes())
}

/// The Markdown text of the report, assuming every plot was written.
pub fn render(report: &RunReport) -> String {
    render_with(report, &[])
}

fn render_with(r: &RunReport, plot_errors: &[Option<String>]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Run report: {}\n", inline(&r.case));

    let _ = writeln!(s, "## Results\n");
    if r.results.is_empty() {
        let _ = writeln!(s, "No results.\n");
    } else {
        let _ = writeln!(s, "| quantity | unit | reference | value | relative error | source |");
        let _ = writeln!(s, "|---|---|---:|---:|---:|---|");
        for row in &r.results {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} |",
                cell(&row.quantity),
                cell(&row.unit),
                row.reference.map(fmt_num).unwrap_or_default(),
                match row.standard_error {
                    Some(se) => format!("{} (standard error)", plus_minus((row.value, se))),
                    None => fmt_num(row.value),
                },
                row.rel_error.map(fmt_percent).unwrap_or_default(),
                cell(row.source.as_deref().unwrap_or("")),
            );
        }
        s.push('\n');
    }

    for t in &r.tables {
        let _ = writeln!(s, "## {}\n", inline(&t.title));
        let _ = writeln!(s, "| {} |", t.header.iter().map(|h| cell(h)).collect::<Vec<_>>().join(" | "));
        let _ = writeln!(s, "|{}", "---|".repeat(t.header.len()));
        for row in &t.rows {
            let _ = writeln!(s, "| {} |", row.iter().map(|c| cell(c)).collect::<Vec<_>>().join(" | "));
        }
        s.push('\n');
    }

    let _ = writeln!(s, "## Run\n");
    let _ = writeln!(s, "| | |\n|---|---|");
    let _ = writeln!(s, "| particles | {} |", r.particles);
    let _ = writeln!(s, "| steps | {} |", r.steps);
    let _ = writeln!(s, "| end time | {} |", fmt_num(r.end_time));
    let _ = writeln!(s, "| wall time | {} s |", fmt_num(r.wall_s));
    let _ = writeln!(s, "| particle-steps/s | {} |", fmt_num(r.particle_steps_per_s));
    let _ = writeln!(s, "| backend | {} |", cell(&r.backend));
    let _ = writeln!(s, "| precision | {} |", cell(&r.precision));
    let _ = writeln!(s, "| resolution | {} |", cell(&r.resolution));
    if r.dx > 0.0 {
        let _ = writeln!(s, "| particle spacing | {} m |", fmt_num(r.dx));
    }
    s.push('\n');

    if !r.bytes_per_particle.is_empty() {
        let _ = writeln!(s, "## Particle state\n");
        let _ = writeln!(s, "| group | bytes per particle |\n|---|---:|");
        for g in &r.bytes_per_particle {
            let _ = writeln!(s, "| {} | {} |", cell(&g.group), g.bytes);
        }
        s.push('\n');
    }

    if !r.notes.is_empty() {
        let _ = writeln!(s, "## Notes\n");
        for n in &r.notes {
            let _ = writeln!(s, "- {}", n.trim().replace('\n', "\n  "));
        }
        s.push('\n');
    }

    if !r.histories.is_empty() {
        let _ = writeln!(s, "## Histories\n");
        for (i, h) in r.histories.iter().enumerate() {
            match plot_errors.get(i).and_then(|e| e.as_deref()) {
                None => {
                    let _ = writeln!(s, "![{}]({})\n", alt_text(&h.name), plot_file_name(h));
                }
                Some(e) => {
                    let _ = writeln!(s, "{}: no plot ({}).\n", inline(&h.name), inline(e));
                }
            }
        }
    }
    s
}

/// A table cell: no line breaks, pipes escaped.
fn cell(text: &str) -> String {
    inline(text).replace('|', "\\|")
}

fn inline(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn alt_text(text: &str) -> String {
    inline(text).replace(['[', ']'], "")
}

/// A value and its standard error as `value ± se`.
pub fn plus_minus((value, se): (f64, f64)) -> String {
    format!("{} ± {}", fmt_num(value), fmt_num(se))
}

/// Up to six significant digits for moderate magnitudes, exponent form otherwise.
pub fn fmt_num(v: f64) -> String {
    if v.is_nan() {
        return "NaN".into();
    }
    if v.is_infinite() {
        return if v > 0.0 { "inf".into() } else { "-inf".into() };
    }
    let a = v.abs();
    if a == 0.0 {
        return "0".into();
    }
    if (1e-3..1e6).contains(&a) {
        let decimals = (5 - a.log10().floor() as i32).max(0) as usize;
        let s = format!("{v:.decimals$}");
        let s = if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.') } else { &s };
        return s.to_string();
    }
    let s = format!("{v:.5e}");
    // Trim the mantissa's trailing zeros: 1.50000e7 → 1.5e7.
    match s.split_once('e') {
        Some((m, e)) => {
            let m = if m.contains('.') { m.trim_end_matches('0').trim_end_matches('.') } else { m };
            format!("{m}e{e}")
        }
        None => s,
    }
}

/// A relative error as a signed percentage: `0.01` → `+1.00 %`; tiny errors in exponent form.
pub fn fmt_percent(rel: f64) -> String {
    if !rel.is_finite() {
        return fmt_num(rel);
    }
    let p = rel * 100.0;
    if p != 0.0 && p.abs() < 0.01 {
        format!("{p:+.2e} %")
    } else {
        format!("{p:+.2} %")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::json::{Curve, GroupBytes, ResultRow, Table};

    #[test]
    fn numbers() {
        assert_eq!(fmt_num(1000.0), "1000");
        assert_eq!(fmt_num(1010.5), "1010.5");
        assert_eq!(fmt_num(0.1), "0.1");
        assert_eq!(fmt_num(-2.5e-7), "-2.5e-7");
        assert_eq!(fmt_num(1.5e7), "1.5e7");
        assert_eq!(fmt_num(123456.7), "123457");
        assert_eq!(fmt_num(f64::NAN), "NaN");
        assert_eq!(fmt_percent(0.01), "+1.00 %");
        assert_eq!(fmt_percent(-0.0234), "-2.34 %");
        assert_eq!(fmt_percent(0.0), "+0.00 %");
        assert_eq!(fmt_percent(-1e-6), "-1.00e-4 %");
    }

    #[test]
    fn render_sections() {
        let r = RunReport {
            case: "dam break".into(),
            backend: "cpu".into(),
            precision: "f64".into(),
            particles: 1234,
            steps: 10,
            wall_s: 1.5,
            particle_steps_per_s: 8226.0,
            results: vec![
                ResultRow::new("front | x", "m", 1.02, Some(1.0)).with_source("Martin & Moyce"),
                ResultRow::new("mass", "kg", 3.0, None),
            ],
            bytes_per_particle: vec![GroupBytes { group: "fluid".into(), bytes: 96 }],
            histories: vec![History {
                name: "Kinetic energy".into(),
                series: vec![Curve::new("Ek", vec![])],
                ..Default::default()
            }],
            notes: vec!["measured\nwith care".into()],
            resolution: "dx = 0.01 m".into(),
            dx: 0.01,
            end_time: 0.5,
            tables: vec![Table {
                title: "At each resolution".into(),
                header: vec!["resolution".into(), "value".into()],
                rows: vec![vec!["ci".into(), "1 | 2".into()]],
            }],
        };
        let md = render(&r);
        assert!(md.starts_with("# Run report: dam break\n"));
        assert!(md.contains("| front \\| x | m | 1 | 1.02 | +2.00 % | Martin & Moyce |"), "{md}");
        assert!(md.contains("| mass | kg |  | 3 |  |  |"), "{md}");
        assert!(md.contains("| fluid | 96 |"));
        assert!(md.contains("## At each resolution\n\n| resolution | value |\n|---|---|\n| ci | 1 \\| 2 |\n"), "{md}");
        assert!(md.contains("| particle spacing | 0.01 m |"), "{md}");
        assert!(md.contains("- measured\n  with care"));
        assert!(md.contains("![Kinetic energy](Kinetic_energy.svg)"));
        let md = render_with(&r, &[Some("bad range".into())]);
        assert!(md.contains("Kinetic energy: no plot (bad range)."));
    }
}
