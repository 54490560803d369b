//! Diagnostics shared by every stage: a map of source files, spans into them, and errors/warnings
//! rendered with file, line, column and a caret under the span (codespan-reporting).

use codespan_reporting::diagnostic::{Diagnostic as CsDiagnostic, Label};
use codespan_reporting::files::SimpleFiles;
use codespan_reporting::term::{self, Config};
use std::fmt;

/// A byte range in one source file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct Span {
    pub file: u32,
    pub start: u32,
    pub end: u32,
}

impl Span {
    pub fn new(file: u32, start: usize, end: usize) -> Span {
        Span { file, start: start as u32, end: end as u32 }
    }
    pub fn to(self, other: Span) -> Span {
        Span { file: self.file, start: self.start.min(other.start), end: self.end.max(other.end) }
    }
}

/// Every source the compiler has read (DSL files, case files), so spans can be shown.
#[derive(Default)]
pub struct Sources {
    files: SimpleFiles<String, String>,
}

impl Sources {
    pub fn new() -> Sources {
        Sources::default()
    }
    pub fn add(&mut self, name: impl Into<String>, text: impl Into<String>) -> u32 {
        self.files.add(name.into(), text.into()) as u32
    }
    pub fn name(&self, file: u32) -> &str {
        self.files.get(file as usize).map(|f| f.name().as_str()).unwrap_or("<unknown>")
    }
    pub fn text(&self, file: u32) -> &str {
        self.files.get(file as usize).map(|f| f.source().as_str()).unwrap_or("")
    }
    pub fn snippet(&self, span: Span) -> &str {
        self.text(span.file).get(span.start as usize..span.end as usize).unwrap_or("")
    }
    /// 1-based line and column of a span's start (the line found by binary search over the
    /// file's line starts, so that locating every equation of a long file stays linear).
    pub fn line_col(&self, span: Span) -> (usize, usize) {
        use codespan_reporting::files::Files;
        let text = self.text(span.file);
        let mut start = (span.start as usize).min(text.len());
        while !text.is_char_boundary(start) {
            start -= 1;
        }
        let id = span.file as usize;
        let Ok(line) = self.files.line_index(id, start) else { return (1, 1) };
        let Ok(range) = self.files.line_range(id, line) else { return (line + 1, 1) };
        let col = text.get(range.start.min(start)..start).map_or(0, |l| l.chars().count());
        (line + 1, col + 1)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    Warning,
    Error,
}

#[derive(Clone, Debug)]
pub struct Diagnostic {
    pub severity: Severity,
    pub code: &'static str,
    pub message: String,
    /// The primary span and what to say under it.
    pub primary: Option<(Span, String)>,
    pub secondary: Vec<(Span, String)>,
    pub notes: Vec<String>,
    pub help: Option<String>,
}

impl Diagnostic {
    pub fn error(code: &'static str, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            severity: Severity::Error,
            code,
            message: message.into(),
            primary: None,
            secondary: vec![],
            notes: vec![],
            help: None,
        }
    }
    pub fn warning(code: &'static str, message: impl Into<String>) -> Diagnostic {
        Diagnostic { severity: Severity::Warning, ..Diagnostic::error(code, message) }
    }
    pub fn at(mut self, span: Span, label: impl Into<String>) -> Diagnostic {
        self.primary = Some((span, label.into()));
        self
    }
    pub fn also(mut self, span: Span, label: impl Into<String>) -> Diagnostic {
        self.secondary.push((span, label.into()));
        self
    }
    pub fn note(mut self, note: impl Into<String>) -> Diagnostic {
        self.notes.push(note.into());
        self
    }
    pub fn help(mut self, help: impl Into<String>) -> Diagnostic {
        self.help = Some(help.into());
        self
    }
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }
}

/// Renders diagnostics as plain text (no colour): what the CLI prints and what the snapshots hold.
pub fn render(sources: &Sources, diags: &[Diagnostic]) -> String {
    let config = Config::default();
    let mut out = String::new();
    for d in diags {
        let cs = match d.severity {
            Severity::Error => CsDiagnostic::error(),
            Severity::Warning => CsDiagnostic::warning(),
        }
        .with_message(&d.message)
        .with_code(d.code);
        let mut labels = vec![];
        if let Some((span, text)) = &d.primary {
            labels.push(Label::primary(span.file as usize, range(*span)).with_message(text));
        }
        for (span, text) in &d.secondary {
            labels.push(Label::secondary(span.file as usize, range(*span)).with_message(text));
        }
        let mut notes = d.notes.clone();
        if let Some(h) = &d.help {
            notes.push(format!("help: {h}"));
        }
        let cs = cs.with_labels(labels).with_notes(notes);
        if term::emit_to_string(&mut out, &config, &sources.files, &cs).is_err() {
            // A span outside its file is a compiler bug; still show the message.
            out.push_str(&format!("{}[{}]: {}\n", sev(d.severity), d.code, d.message));
        }
    }
    out
}

fn range(span: Span) -> std::ops::Range<usize> {
    span.start as usize..span.end as usize
}

fn sev(s: Severity) -> &'static str {
    match s {
        Severity::Error => "error",
        Severity::Warning => "warning",
    }
}

/// A list of diagnostics that is an error as a whole (for `Result`).
#[derive(Debug, Default)]
pub struct Diagnostics(pub Vec<Diagnostic>);

impl Diagnostics {
    pub fn has_errors(&self) -> bool {
        self.0.iter().any(|d| d.is_error())
    }
}

impl fmt::Display for Diagnostics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for d in &self.0 {
            writeln!(f, "{}[{}]: {}", sev(d.severity), d.code, d.message)?;
        }
        Ok(())
    }
}

/// Edit distance, for "did you mean" suggestions.
pub fn closest<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let candidates: Vec<&str> = candidates.into_iter().collect();
    let mut best: Option<(usize, &str)> = None;
    for &c in &candidates {
        let d = levenshtein(name, c);
        let limit = (name.len().max(c.len()) / 3).max(1);
        if d <= limit && best.is_none_or(|(bd, bc)| d < bd || (d == bd && c < bc)) {
            best = Some((d, c));
        }
    }
    // Else the one candidate the name begins (`energy` for `energy_factor`).
    let mut begun = candidates.iter().filter(|c| name.len() >= 3 && c.starts_with(name));
    best.map(|(_, c)| c).or_else(|| match (begun.next(), begun.next()) {
        (Some(c), None) => Some(*c),
        _ => None,
    })
}

fn levenshtein(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.iter().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::closest;

    #[test]
    fn closest_suggests_a_near_spelling_else_the_one_candidate_the_name_begins() {
        assert_eq!(closest("enrgy_factor", ["speed_factor", "energy_factor"]), Some("energy_factor"));
        assert_eq!(closest("energy", ["speed_factor", "energy_factor"]), Some("energy_factor"));
        // Two candidates begin with it, or it is too short to mean one: no guess.
        assert_eq!(closest("energy", ["energy_factor", "energy_floor"]), None);
        assert_eq!(closest("en", ["energy_factor"]), None);
    }
}
