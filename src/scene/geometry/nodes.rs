//! Imported node lists: CSV (`x,y,z[,volume]`) and the `*NODE` sections of an LS-DYNA keyword deck,
//! with errors that point at a line and column; and their conversion to [`Particles`].

use super::fill::Particles;
use super::primitive::check_dim;
use super::spacing::estimate_spacing;
use super::{GeometryError, MAX_PARTICLES};
use std::fmt;

/// Node positions read from a file, with per-node volumes when the file gives them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NodeList {
    /// Node positions (m), as read (all three coordinates).
    pub positions: Vec<[f64; 3]>,
    /// Per-node volumes (m³), when the file has a volume column.
    pub volumes: Option<Vec<f64>>,
}

/// A malformed node file: where (1-based line and column, in characters) and what.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeError {
    /// The file's name, as given to the reader.
    pub source_name: String,
    /// The 1-based line.
    pub line: usize,
    /// The 1-based column (in characters).
    pub column: usize,
    /// What is wrong, e.g. "expected a number, found `abc`".
    pub message: String,
}

impl fmt::Display for NodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}: {}", self.source_name, self.line, self.column, self.message)
    }
}

impl std::error::Error for NodeError {}

/// A field of a line: its 1-based column and its text (trimmed).
struct Field<'a> {
    column: usize,
    text: &'a str,
}

/// Builds [`NodeError`]s for one source.
struct Errors<'a> {
    source_name: &'a str,
}

impl Errors<'_> {
    fn at(&self, line: usize, column: usize, message: impl Into<String>) -> NodeError {
        NodeError { source_name: self.source_name.to_string(), line, column, message: message.into() }
    }

    fn number(&self, line: usize, f: &Field, what: &str) -> NodeError {
        let found = if f.text.is_empty() { "nothing".to_string() } else { format!("`{}`", f.text) };
        self.at(line, f.column, format!("expected {what}, found {found}"))
    }
}

/// Parses a decimal number (`-1.5`, `2`, `1.0e-3`, `1E+3`, `.5`); `None` for anything else,
/// including `inf` and `nan`.
fn parse_plain(s: &str) -> Option<f64> {
    let ok = !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit() || b"+-.eE".contains(&b));
    let v: f64 = if ok { s.parse().ok()? } else { return None };
    v.is_finite().then_some(v)
}

/// Parses a Fortran-style real as LS-DYNA writes them: a plain number, a `d`/`D` exponent
/// (`1.0D-3`), or an exponent without a letter (`1.0-3` = 1.0e-3, `2.5+2` = 250).
pub(crate) fn parse_fortran(s: &str) -> Option<f64> {
    if let Some(v) = parse_plain(s) {
        return Some(v);
    }
    let s = s.replace(['d', 'D'], "e");
    if let Some(v) = parse_plain(&s) {
        return Some(v);
    }
    let b = s.as_bytes();
    let split =
        (1..b.len()).find(|&i| (b[i] == b'+' || b[i] == b'-') && (b[i - 1].is_ascii_digit() || b[i - 1] == b'.'))?;
    if s.contains(['e', 'E']) {
        return None;
    }
    parse_plain(&format!("{}e{}", &s[..split], &s[split..]))
}

/// Splits `line` at `sep`, each field trimmed, with the 1-based column of its first character (or of
/// where it would be, for an empty field).
fn split_fields(line: &str, sep: char) -> Vec<Field<'_>> {
    let mut fields = Vec::new();
    let mut start = 0;
    for piece in line.split(sep) {
        let lead = piece.len() - piece.trim_start().len();
        let column = line[..start + lead].chars().count() + 1;
        fields.push(Field { column, text: piece.trim() });
        start += piece.len() + sep.len_utf8();
    }
    fields
}

/// Reads a CSV node list: lines `x,y,z` or `x,y,z,volume` (all lines alike). Blank lines and `#`
/// comments (whole-line or trailing) are skipped, and the first line may be a header of non-numeric
/// words (`x,y,z,volume`). Numbers must be finite; volumes positive.
pub fn read_csv_nodes(text: &str, source_name: &str) -> Result<NodeList, NodeError> {
    let err = Errors { source_name };
    let mut nodes = NodeList::default();
    let mut width: Option<(usize, usize)> = None;
    let mut first_content = true;
    let mut last = 1;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        last = line_no;
        let line = raw.trim_start_matches('\u{feff}');
        let line = line.split('#').next().unwrap_or("");
        if line.trim().is_empty() {
            continue;
        }
        let fields = split_fields(line, ',');
        let header = first_content && fields.iter().all(|f| !f.text.is_empty() && parse_plain(f.text).is_none());
        first_content = false;
        if !header {
            csv_line(&err, line_no, line, &fields, &mut width, &mut nodes)?;
        }
    }
    if nodes.positions.is_empty() {
        return Err(err.at(last, 1, "no nodes: expected lines `x,y,z` or `x,y,z,volume`"));
    }
    check_count(&err, last, nodes.positions.len())?;
    Ok(nodes)
}

fn check_count(err: &Errors, line: usize, n: usize) -> Result<(), NodeError> {
    if n as u64 > MAX_PARTICLES {
        return Err(err.at(line, 1, format!("{n} nodes, more than the limit of {MAX_PARTICLES}")));
    }
    Ok(())
}

/// Parses one CSV data line into `nodes`; `width` is the field count of the first data line and
/// its line number.
fn csv_line(
    err: &Errors,
    line_no: usize,
    line: &str,
    fields: &[Field],
    width: &mut Option<(usize, usize)>,
    nodes: &mut NodeList,
) -> Result<(), NodeError> {
    let n = fields.len();
    let end = line.trim_end().chars().count() + 1;
    if n != 3 && n != 4 {
        let msg = format!("expected 3 fields (x,y,z) or 4 (x,y,z,volume), found {n}");
        return Err(err.at(line_no, fields.get(4).map_or(end, |f| f.column), msg));
    }
    let (w, first) = *width.get_or_insert((n, line_no));
    if n != w {
        let msg = format!("expected {w} fields like line {first}, found {n}");
        return Err(err.at(line_no, fields.get(w).map_or(end, |f| f.column), msg));
    }
    let mut v = [0.0; 4];
    for (slot, f) in v.iter_mut().zip(fields) {
        *slot = parse_plain(f.text).ok_or_else(|| err.number(line_no, f, "a number"))?;
    }
    nodes.positions.push([v[0], v[1], v[2]]);
    if n == 4 {
        if v[3] <= 0.0 {
            return Err(err.number(line_no, &fields[3], "a positive volume"));
        }
        nodes.volumes.get_or_insert_with(Vec::new).push(v[3]);
    }
    Ok(())
}

/// The column widths of a `*NODE` card: nid, x, y, z, tc, rc.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Layout {
    /// `I8, 3E16, 2F8`: the standard format.
    Standard,
    /// `I10, 3E16, 2F8`: `*NODE %`, for node ids beyond 8 digits.
    Wide,
    /// Six fields of 20 columns: `*NODE +` or `*KEYWORD LONG=Y`.
    Long,
}

impl Layout {
    fn widths(self) -> [usize; 6] {
        match self {
            Layout::Standard => [8, 16, 16, 16, 8, 8],
            Layout::Wide => [10, 16, 16, 16, 8, 8],
            Layout::Long => [20; 6],
        }
    }

    fn describe(self) -> &'static str {
        match self {
            Layout::Standard => "nid in columns 1-8, x 9-24, y 25-40, z 41-56, tc 57-64, rc 65-72",
            Layout::Wide => "nid in columns 1-10, x 11-26, y 27-42, z 43-58, tc 59-66, rc 67-74",
            Layout::Long => "nid in columns 1-20, x 21-40, y 41-60, z 61-80, tc 81-100, rc 101-120",
        }
    }
}

/// The state of the keyword scan: the default layout and the `*NODE` section we are in, if any.
struct DeckState {
    long: bool,
    section: Option<Layout>,
    sections: usize,
}

/// Reads the nodes of an LS-DYNA keyword deck: every `*NODE` section (the data lines after `*NODE`
/// up to the next line starting with `*`), concatenated in file order. Other keywords, including
/// `*NODE_…` variants and `*INCLUDE` (not followed), are skipped; `$` lines are comments and blank
/// lines are skipped.
///
/// A node line is either comma-separated, `nid, x, y, z[, tc, rc]`, or fixed width: nid in columns
/// 1–8, x 9–24, y 25–40, z 41–56, tc 57–64, rc 65–72 (`*NODE %`: nid 1–10 and the rest shifted by
/// 2; `*NODE +` or `*KEYWORD LONG=Y`: six fields of 20 columns). As in LS-DYNA, a blank coordinate
/// is 0. Reals may be written Fortran style: `1.0E-3`, `1.0e-3`, `1.0D-3`, and `1.0-3` (an exponent
/// without its letter) all read as 0.001. Node ids must be integers; `tc` and `rc` must be numbers
/// when present and are otherwise ignored.
pub fn read_lsdyna_nodes(text: &str, source_name: &str) -> Result<NodeList, NodeError> {
    let err = Errors { source_name };
    let mut state = DeckState { long: false, section: None, sections: 0 };
    let mut positions = Vec::new();
    let mut last = 1;
    for (i, raw) in text.lines().enumerate() {
        last = i + 1;
        let line = raw.trim_start_matches('\u{feff}').trim_end();
        let head = line.trim_start();
        if head.starts_with('$') || head.is_empty() {
            continue;
        }
        if head.starts_with('*') {
            state.keyword(head);
            continue;
        }
        if let Some(layout) = state.section {
            positions.push(node_line(&err, i + 1, line, layout)?);
        }
    }
    if positions.is_empty() {
        let what = if state.sections == 0 { "no *NODE section" } else { "no nodes in the *NODE sections" };
        return Err(err.at(last, 1, what));
    }
    check_count(&err, last, positions.len())?;
    Ok(NodeList { positions, volumes: None })
}

impl DeckState {
    /// Updates the state on a keyword line (`head` starts with `*`).
    fn keyword(&mut self, head: &str) {
        let upper = head.to_ascii_uppercase();
        let (name, rest) = upper.split_once(char::is_whitespace).unwrap_or((&upper, ""));
        let (name, modifier) = match name.strip_suffix(['%', '+', '-']) {
            Some(stem) => (stem, &name[stem.len()..]),
            None => (name, rest.trim()),
        };
        if name == "*KEYWORD" {
            let flat: String = rest.chars().filter(|c| !c.is_whitespace()).collect();
            self.long = flat.contains("LONG=Y") || (self.long && !flat.contains("LONG=S"));
        }
        let layout = match modifier {
            "%" => Layout::Wide,
            "+" => Layout::Long,
            "-" => Layout::Standard,
            _ if self.long => Layout::Long,
            _ => Layout::Standard,
        };
        self.section = (name == "*NODE").then_some(layout);
        self.sections += usize::from(self.section.is_some());
    }
}

/// Parses one node line, comma-separated or fixed width.
fn node_line(err: &Errors, line_no: usize, line: &str, layout: Layout) -> Result<[f64; 3], NodeError> {
    let fields = if line.contains(',') {
        let fields = split_fields(line, ',');
        if !(4..=6).contains(&fields.len()) {
            let msg =
                format!("expected 4 to 6 comma-separated fields (nid, x, y, z[, tc, rc]), found {}", fields.len());
            let end = line.trim_end().chars().count() + 1;
            return Err(err.at(line_no, fields.get(6).map_or(end, |f| f.column), msg));
        }
        fields
    } else {
        fixed_fields(err, line_no, line, layout)?
    };
    node_values(err, line_no, &fields, layout)
}

/// Cuts a fixed-width line into its fields (trimmed; missing fields are empty).
fn fixed_fields<'a>(err: &Errors, line_no: usize, line: &'a str, layout: Layout) -> Result<Vec<Field<'a>>, NodeError> {
    let bounds: Vec<usize> = line.char_indices().map(|(b, _)| b).chain([line.len()]).collect();
    let n_chars = bounds.len() - 1;
    let byte_at = |col: usize| bounds[col.min(n_chars)];
    let mut fields = Vec::with_capacity(6);
    let mut start = 0;
    for w in layout.widths() {
        let piece = &line[byte_at(start)..byte_at(start + w)];
        let lead = piece.chars().count() - piece.trim_start().chars().count();
        fields.push(Field { column: start + lead + 1, text: piece.trim() });
        start += w;
    }
    let tail = &line[byte_at(start)..];
    if !tail.trim().is_empty() {
        let lead = tail.chars().count() - tail.trim_start().chars().count();
        let msg =
            format!("unexpected text after the last field ({}; or separate the fields with commas)", layout.describe());
        return Err(err.at(line_no, start + lead + 1, msg));
    }
    Ok(fields)
}

/// Reads nid, x, y, z (and checks tc, rc) from the fields of a node line.
fn node_values(err: &Errors, line_no: usize, fields: &[Field], layout: Layout) -> Result<[f64; 3], NodeError> {
    let nid = &fields[0];
    if nid.text.parse::<i64>().is_err() {
        let hint =
            if nid.text.contains(char::is_whitespace) { format!(" ({})", layout.describe()) } else { String::new() };
        let e = err.number(line_no, nid, "an integer node id");
        return Err(NodeError { message: e.message + &hint, ..e });
    }
    let mut x = [0.0; 3];
    for (slot, f) in x.iter_mut().zip(&fields[1..4]) {
        if !f.text.is_empty() {
            *slot = parse_fortran(f.text).ok_or_else(|| err.number(line_no, f, "a number"))?;
        }
    }
    if let Some(f) = fields.iter().skip(4).find(|f| !f.text.is_empty() && parse_fortran(f.text).is_none()) {
        return Err(err.number(line_no, f, "a number (tc or rc)"));
    }
    Ok(x)
}

impl NodeList {
    /// Turns the nodes into particles in `dim` dimensions: the file's volumes when it has them
    /// (spacing = volume^(1/dim)), otherwise spacing from [`estimate_spacing`] and volume
    /// `spacing^dim`. The coordinates beyond `dim` must be the same for every node (a 2D model's
    /// nodes lie in one plane z = const) and are set to 0.
    pub fn to_particles(&self, dim: usize) -> Result<Particles, GeometryError> {
        check_dim(dim)?;
        let n = self.positions.len();
        if n == 0 {
            return Err(GeometryError::Nodes("the node list is empty".into()));
        }
        let positions = self.planar_positions(dim)?;
        let spacing = match &self.volumes {
            Some(v) if v.len() == n => v.iter().map(|v| v.powf(1.0 / dim as f64)).collect(),
            Some(v) => return Err(GeometryError::Nodes(format!("{} volumes for {n} nodes", v.len()))),
            None => estimate_spacing(&positions, dim),
        };
        if let Some(i) = spacing.iter().position(|s: &f64| !(s.is_finite() && *s > 0.0)) {
            return Err(bad_spacing(i, positions[i], n));
        }
        let mut p = Particles::from_parts(positions, spacing, dim, None);
        if let Some(v) = &self.volumes {
            p.volumes.clone_from(v);
        }
        Ok(p)
    }

    /// The positions with the coordinates beyond `dim` checked constant and zeroed.
    fn planar_positions(&self, dim: usize) -> Result<Vec<[f64; 3]>, GeometryError> {
        let first = self.positions[0];
        let mut out = Vec::with_capacity(self.positions.len());
        for (i, p) in self.positions.iter().enumerate() {
            if let Some(a) = (dim..3).find(|&a| p[a] != first[a]) {
                let (n, v, v1) = (i + 1, p[a], first[a]);
                let msg = format!(
                    "node {n} has coordinate {a} = {v} but node 1 has {v1}: \
                     the nodes of a {dim}D model must share their coordinates beyond the first {dim}"
                );
                return Err(GeometryError::Nodes(msg));
            }
            out.push(super::primitive::truncate(*p, dim));
        }
        Ok(out)
    }
}

fn bad_spacing(i: usize, p: [f64; 3], n: usize) -> GeometryError {
    let msg = if n == 1 {
        "a single node has no neighbours to estimate its volume from; give its volume".to_string()
    } else {
        format!(
            "node {} at {p:?} coincides with its nearest neighbours (or is not finite); cannot estimate its volume",
            i + 1
        )
    };
    GeometryError::Nodes(msg)
}
