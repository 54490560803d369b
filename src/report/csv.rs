//! Time histories as CSV (`histories.csv`), one column per probe, for plotting in any tool.
//!
//! Every history whose x axis is time contributes one column per curve; the rows are the union of
//! the sampling times, in order, with an empty cell where a probe was not sampled (probes may be
//! sampled every few steps). Values are written with Rust's shortest round-trip formatting.

use super::json::History;

/// The text of `histories.csv` for a run's histories, or `None` when none is a time history.
pub fn histories_csv(histories: &[History]) -> Option<String> {
    let columns: Vec<(String, &[(f64, f64)])> = histories
        .iter()
        .filter(|h| is_time(h))
        .flat_map(|h| h.series.iter().map(move |c| (column_name(h, &c.name), c.points.as_slice())))
        .collect();
    if columns.is_empty() {
        return None;
    }
    let mut times: Vec<f64> = columns.iter().flat_map(|(_, p)| p.iter().map(|q| q.0)).collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    let mut out = String::from("time [s]");
    for (name, _) in &columns {
        out.push(',');
        out.push_str(&quote(name));
    }
    out.push('\n');
    let mut next = vec![0usize; columns.len()];
    for t in times {
        out.push_str(&format!("{t:?}"));
        for (k, (_, points)) in columns.iter().enumerate() {
            out.push(',');
            if let Some(&(_, v)) = points.get(next[k]).filter(|p| p.0 == t) {
                out.push_str(&format!("{v:?}"));
                next[k] += 1;
            }
        }
        out.push('\n');
    }
    Some(out)
}

/// The text of a profile: a header of column names, then one row per particle.
pub fn profile_csv(columns: &[(String, Vec<f64>)]) -> String {
    let mut out = columns.iter().map(|(name, _)| quote(name)).collect::<Vec<_>>().join(",");
    out.push('\n');
    for k in 0..columns.first().map_or(0, |c| c.1.len()) {
        let row: Vec<String> = columns.iter().map(|(_, v)| format!("{:?}", v[k])).collect();
        out.push_str(&row.join(","));
        out.push('\n');
    }
    out
}

fn is_time(h: &History) -> bool {
    h.x_label == "t [s]"
}

/// A probe's column: its y label (`name [unit]`), with the curve's name when a history has several.
fn column_name(h: &History, curve: &str) -> String {
    if h.series.len() > 1 {
        format!("{} ({curve})", h.y_label)
    } else {
        h.y_label.clone()
    }
}

/// A CSV field, quoted when it holds a comma or a quote.
fn quote(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::Curve;

    fn history(name: &str, points: Vec<(f64, f64)>) -> History {
        History {
            name: name.into(),
            x_label: "t [s]".into(),
            y_label: format!("{name} [m]"),
            series: vec![Curve::new(name.to_string(), points)],
            reference: None,
            log_log: false,
        }
    }

    #[test]
    fn probes_sampled_at_different_times_share_one_time_column() {
        let histories = [
            history("a", vec![(0.0, 1.0), (0.5, 2.0), (1.0, 3.0)]),
            history("b, wide", vec![(0.0, -1.0), (1.0, -3.0)]),
        ];
        let csv = histories_csv(&histories).expect("a csv");
        assert_eq!(csv, "time [s],a [m],\"b, wide [m]\"\n0.0,1.0,-1.0\n0.5,2.0,\n1.0,3.0,-3.0\n");
    }
}
