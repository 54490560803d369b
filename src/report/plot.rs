//! SVG line plots of run histories, drawn with `plotters`' SVG backend.
//!
//! plotters is used without its default features: no font-kit and no system fonts. The SVG
//! backend writes text as `<text>` elements and leaves the rendering to the SVG viewer; only the
//! layout uses a crude text-size estimate.

use std::path::Path;

use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::json::History;

const WIDTH: u32 = 800;
const HEIGHT: u32 = 500;

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// Plots `h` as an SVG at `path`: labelled axes (both logarithmic when `h.log_log`), one line per
/// curve with a legend, and the optional reference as a dashed horizontal line.
///
/// Non-finite points are skipped; a curve with a single finite point is drawn as a marker; an
/// empty history, or one whose values are all equal, gets a padded range instead of a degenerate
/// one.
pub fn plot_history(path: &Path, h: &History) -> Result<(), String> {
    // On log–log axes the points are drawn as their base-10 logarithms and the ticks labelled with
    // the values themselves.
    let axis = |v: f64| if h.log_log { v.log10() } else { v };
    let curves: Vec<(&str, Vec<(f64, f64)>)> = h
        .series
        .iter()
        .map(|c| {
            let points = c.points.iter().map(|&(x, y)| (axis(x), axis(y)));
            (c.name.as_str(), points.filter(|(x, y)| x.is_finite() && y.is_finite()).collect())
        })
        .collect();
    let reference = h.reference.map(axis).filter(|r| r.is_finite());
    let tick = |v: f64, span: f64| if h.log_log { fmt_tick(10f64.powf(v), 0.0) } else { fmt_tick(v, span) };

    let xs = curves.iter().flat_map(|(_, p)| p.iter().map(|&(x, _)| x));
    let ys = curves.iter().flat_map(|(_, p)| p.iter().map(|&(_, y)| y)).chain(reference);
    let (x0, x1) = axis_range(xs, 0.0)?;
    let (y0, y1) = axis_range(ys, 0.05)?;

    let err = |e: &dyn std::fmt::Display| format!("plot `{}` ({}): {e}", h.name, path.display());
    let root = SVGBackend::new(path, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(&h.name, ("sans-serif", 24))
        .margin(15)
        .x_label_area_size(50)
        .y_label_area_size(90)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc(h.x_label.as_str())
        .y_desc(h.y_label.as_str())
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 18))
        .x_label_formatter(&|v| tick(*v, x1 - x0))
        .y_label_formatter(&|v| tick(*v, y1 - y0))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(|e| err(&e))?;

    let mut labelled = false;
    for (i, (name, points)) in curves.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        let style = ShapeStyle::from(&color).stroke_width(2);
        let anno = if points.len() == 1 {
            chart.draw_series(points.iter().map(|&p| Circle::new(p, 4, style.filled()))).map_err(|e| err(&e))?
        } else {
            chart.draw_series(LineSeries::new(points.iter().copied(), style)).map_err(|e| err(&e))?
        };
        if !name.is_empty() {
            anno.label(*name).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
            labelled = true;
        }
    }
    if let Some(r) = reference {
        let style = ShapeStyle::from(&BLACK).stroke_width(1);
        chart
            .draw_series(DashedLineSeries::new(vec![(x0, r), (x1, r)], 8, 5, style))
            .map_err(|e| err(&e))?
            .label("reference")
            .legend(move |(x, y)| DashedPathElement::new(vec![(x, y), (x + 20, y)], 5, 3, style));
        labelled = true;
    }
    if labelled {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

/// The range of finite `values`, padded by `pad` of its span on each side; a default range for no
/// values and a widened one for a single value.
fn axis_range(values: impl Iterator<Item = f64>, pad: f64) -> Result<(f64, f64), String> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return Ok((0.0, 1.0));
    }
    let span = hi - lo;
    if !span.is_finite() {
        return Err(format!("cannot plot values spanning {lo:e} to {hi:e}"));
    }
    let scale = lo.abs().max(hi.abs());
    if span <= scale * 1e-12 {
        // All equal (up to rounding): centre the value in a range of ±10 % of its magnitude.
        let half = if scale > 0.0 { scale * 0.1 } else { 1.0 };
        let mid = 0.5 * (lo + hi);
        return Ok((mid - half, mid + half));
    }
    Ok((lo - pad * span, hi + pad * span))
}

/// Compact tick labels: plain decimals for moderate magnitudes, exponent form otherwise; `0` for
/// rounding noise (|v| below 1e-9 of the axis span).
fn fmt_tick(v: f64, span: f64) -> String {
    let a = v.abs();
    if a <= span.abs() * 1e-9 {
        "0".into()
    } else if (1e-3..1e5).contains(&a) {
        let s = format!("{v:.6}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        if s == "-0" {
            "0".into()
        } else {
            s.to_string()
        }
    } else {
        format!("{v:.2e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::json::Curve;

    fn tmpdir(tag: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("pairsum-report-plot-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn hist(series: Vec<Curve>, reference: Option<f64>) -> History {
        History {
            name: "energy".into(),
            x_label: "t [s]".into(),
            y_label: "E [J]".into(),
            series,
            reference,
            log_log: false,
        }
    }

    #[test]
    fn writes_svg_with_names_labels_and_reference() {
        let dir = tmpdir("basic");
        let path = dir.join("energy.svg");
        let a = Curve::new("kinetic", (0..50).map(|i| (i as f64 * 0.1, (i as f64 * 0.1).sin())).collect());
        let b = Curve::new("potential", (0..50).map(|i| (i as f64 * 0.1, (i as f64 * 0.1).cos())).collect());
        plot_history(&path, &hist(vec![a, b], Some(0.5))).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..100.min(svg.len())]);
        for text in ["kinetic", "potential", "reference", "energy", "t [s]", "E [J]"] {
            assert!(svg.contains(text), "missing {text}");
        }
        assert!(svg.contains("<text"));
        assert!(svg.contains("<polyline"));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn survives_degenerate_inputs() {
        let dir = tmpdir("degenerate");
        let cases = [
            ("none", hist(vec![], None)),
            ("empty", hist(vec![Curve::new("empty", vec![])], None)),
            ("empty_ref", hist(vec![Curve::new("empty", vec![])], Some(3.0))),
            ("single", hist(vec![Curve::new("one", vec![(1.0, 2.0)])], None)),
            ("zero", hist(vec![Curve::new("zero", vec![(0.0, 0.0)])], Some(0.0))),
            (
                "nan",
                hist(vec![Curve::new("nan", vec![(0.0, f64::NAN), (f64::NAN, 1.0), (1.0, 2.0), (2.0, 3.0)])], None),
            ),
            ("all_nan", hist(vec![Curve::new("all nan", vec![(f64::NAN, f64::NAN); 3])], Some(f64::NAN))),
            ("inf", hist(vec![Curve::new("inf", vec![(0.0, f64::INFINITY), (1.0, 1.0), (2.0, 1.5)])], None)),
            ("flat", hist(vec![Curve::new("flat", (0..10).map(|i| (i as f64, 7.5)).collect())], Some(7.5))),
            ("flat_x", hist(vec![Curve::new("flat x", vec![(2.0, 1.0), (2.0, 3.0)])], None)),
            ("tiny", hist(vec![Curve::new("tiny", vec![(0.0, 1e-300), (1e-300, 2e-300)])], None)),
            ("unnamed", hist(vec![Curve::new("", vec![(0.0, 1.0), (1.0, 2.0)])], None)),
        ];
        for (tag, h) in cases {
            let path = dir.join(format!("{tag}.svg"));
            plot_history(&path, &h).unwrap_or_else(|e| panic!("{tag}: {e}"));
            let svg = std::fs::read_to_string(&path).unwrap();
            assert!(svg.len() > 100 && svg.contains("</svg>"), "{tag}");
            for c in &h.series {
                assert!(svg.contains(&c.name), "{tag}: missing {}", c.name);
            }
        }
        let huge = hist(vec![Curve::new("huge", vec![(0.0, -f64::MAX), (1.0, f64::MAX)])], None);
        assert!(plot_history(&dir.join("huge.svg"), &huge).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn log_log_axes_label_ticks_with_values_and_drop_non_positive_points() {
        let dir = tmpdir("loglog");
        let path = dir.join("error.svg");
        let mut h =
            hist(vec![Curve::new("error", vec![(10.0, 0.1), (100.0, 0.01), (1000.0, 0.001), (0.0, 1.0)])], None);
        h.log_log = true;
        plot_history(&path, &h).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        // Ticks at powers of ten read as the values, not as their logarithms (1 … 3).
        assert!(svg.contains("\n100\n") && svg.contains("\n0.01\n"), "{svg}");
        assert!(svg.contains("<polyline"));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn ranges() {
        assert_eq!(axis_range([].into_iter(), 0.05).unwrap(), (0.0, 1.0));
        assert_eq!(axis_range([0.0, 0.0].into_iter(), 0.05).unwrap(), (-1.0, 1.0));
        let (lo, hi) = axis_range([10.0].into_iter(), 0.05).unwrap();
        assert!((lo - 9.0).abs() < 1e-12 && (hi - 11.0).abs() < 1e-12);
        assert_eq!(axis_range([0.0, 2.0].into_iter(), 0.0).unwrap(), (0.0, 2.0));
        assert_eq!(fmt_tick(0.25, 1.0), "0.25");
        assert_eq!(fmt_tick(3.0, 1.0), "3");
        assert_eq!(fmt_tick(1.5e7, 1e7), "1.50e7");
        assert_eq!(fmt_tick(-2.22e-16, 2.0), "0");
        assert_eq!(fmt_tick(2e-20, 1e-19), "2.00e-20");
    }
}
