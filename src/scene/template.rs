//! Case-file parameters: a case may write `${name}` anywhere (inside strings, e.g.
//! `velocity = [0, 0, "-${v_impact} m/s"]`) and give defaults in `[parameters]`; a study or
//! `pairsum run --set name=value` changes them. Substitution is textual and keeps line numbers.

use crate::diag::{Diagnostic, Span};

pub struct TemplateError {
    pub start: usize,
    pub end: usize,
    pub message: String,
    /// The entry of `set` the error is about (a name the case has no parameter for): it was given
    /// outside the text, so `start..end` says nothing.
    pub set_entry: Option<usize>,
    /// The text is not TOML (with its placeholders read as values): a case-file error, not one of
    /// its parameters.
    pub not_toml: bool,
}

impl TemplateError {
    pub fn diagnostic(&self, file: u32) -> Diagnostic {
        Diagnostic::error("C0026", self.message.clone()).at(Span::new(file, self.start, self.end), "here")
    }
}

fn as_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// The case text read as TOML with every `${name}` replaced by 0, so that the `[parameters]` and
/// the resolutions can be read before the values are known (a placeholder may stand for a number).
/// The 0 is padded with spaces to the placeholder's length, so that an error's span is the text's.
pub fn skeleton(text: &str) -> Result<toml::Table, toml::de::Error> {
    toml::from_str::<toml::Table>(&skeleton_text(text))
}

/// The case text with every `${name}` replaced by a 0 padded to its length (see [`skeleton`]).
pub fn skeleton_text(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(k) = rest.find("${") {
        out.push_str(&rest[..k]);
        match rest[k..].find('}') {
            Some(close) => {
                out.push('0');
                out.push_str(&" ".repeat(close));
                rest = &rest[k + close + 1..];
            }
            None => {
                rest = &rest[k..];
                break;
            }
        }
    }
    out.push_str(rest);
    out
}

/// The case text with every `${name}` replaced by its value: `set` first, then `[parameters]`.
pub fn expand(text: &str, set: &[(String, String)]) -> Result<String, TemplateError> {
    if !text.contains("${") && set.is_empty() {
        return Ok(text.to_string());
    }
    // A text that is not TOML is reported as such here: its parameters cannot be read.
    let table = skeleton(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        TemplateError {
            start: span.start,
            end: span.end,
            message: e.message().to_string(),
            set_entry: None,
            not_toml: true,
        }
    })?;
    let defaults = table.get("parameters").and_then(|p| p.as_table()).cloned().unwrap_or_default();
    for (k, (name, _)) in set.iter().enumerate() {
        if !defaults.contains_key(name) {
            let names: Vec<&String> = defaults.keys().collect();
            return Err(TemplateError {
                start: 0,
                end: 0,
                message: format!("the case has no parameter `{name}` to set (its parameters: {names:?})"),
                set_entry: Some(k),
                not_toml: false,
            });
        }
    }
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    let mut at = 0;
    while let Some(k) = rest.find("${") {
        out.push_str(&rest[..k]);
        let after = &rest[k + 2..];
        let Some(close) = after.find('}') else {
            return Err(TemplateError {
                start: at + k,
                end: at + k + 2,
                message: "`${` without a closing `}`".into(),
                set_entry: None,
                not_toml: false,
            });
        };
        let name = &after[..close];
        let value = match set.iter().rev().find(|(n, _)| n == name) {
            Some((_, v)) => v.clone(),
            None => match defaults.get(name) {
                Some(v) => as_text(v),
                None => {
                    return Err(TemplateError {
                        start: at + k,
                        end: at + k + 3 + close,
                        message: format!("`${{{name}}}` names no entry of `[parameters]`"),
                        set_entry: None,
                        not_toml: false,
                    })
                }
            },
        };
        out.push_str(&value);
        let consumed = k + 3 + close;
        rest = &rest[consumed..];
        at += consumed;
    }
    out.push_str(rest);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placeholders_take_set_values_then_defaults() {
        let text = "[parameters]\nv = \"298\"\nt = 8\n[b]\nvelocity = \"-${v} m/s\"\nthick = \"${t} mm\"\n";
        let out = expand(text, &[("v".into(), "250.8".into())]).ok().expect("expands");
        assert!(out.contains("velocity = \"-250.8 m/s\"") && out.contains("thick = \"8 mm\""), "{out}");
        assert_eq!(out.lines().count(), text.lines().count());
        assert!(expand("x = \"${nope}\"", &[]).expect_err("error").message.contains("nope"));
    }

    #[test]
    fn a_text_that_is_not_toml_is_reported_where_it_breaks_not_as_a_missing_parameter() {
        let text = "[parameters]\nv = 1\n[b]\nspeed = \"${v} m/s\"\ntolerance = TOL\n";
        let e = expand(text, &[]).expect_err("an error");
        assert_eq!(&text[e.start..e.start + 3], "TOL", "{}", e.message);
        assert!(!e.message.contains("names no entry"), "{}", e.message);
    }
}
