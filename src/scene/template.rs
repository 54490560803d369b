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
        let value_of = |name: &str| match set.iter().rev().find(|(n, _)| n == name) {
            Some((_, v)) => Some(v.clone()),
            None => defaults.get(name).map(as_text),
        };
        let value = match value_of(name) {
            Some(v) => v,
            None if is_arithmetic(name) => arithmetic(name, &value_of).map_err(|why| TemplateError {
                start: at + k,
                end: at + k + 3 + close,
                message: format!("`${{{name}}}`: {why}"),
                set_entry: None,
                not_toml: false,
            })?,
            None => {
                return Err(TemplateError {
                    start: at + k,
                    end: at + k + 3 + close,
                    message: format!("`${{{name}}}` names no entry of `[parameters]`"),
                    set_entry: None,
                    not_toml: false,
                })
            }
        };
        out.push_str(&value);
        let consumed = k + 3 + close;
        rest = &rest[consumed..];
        at += consumed;
    }
    out.push_str(rest);
    Ok(out)
}

/// Whether a placeholder is arithmetic (`${radius + phase * 4 / coarse}`) rather than a name:
/// it holds more than letters, digits and `_` (a parameter so named is found before this asks).
fn is_arithmetic(text: &str) -> bool {
    !text.chars().all(|c| c.is_alphanumeric() || c == '_')
}

/// The value of an arithmetic placeholder: numbers and parameters with a number for value,
/// `+ - * /`, unary minus and parentheses, as text (Rust's shortest form of the `f64`).
fn arithmetic(text: &str, value_of: &dyn Fn(&str) -> Option<String>) -> Result<String, String> {
    let tokens = tokens(text)?;
    let mut p = Parser { tokens: &tokens, at: 0, value_of };
    let v = p.sum()?;
    if p.at < tokens.len() {
        return Err(format!("`{}` is not expected here", tokens[p.at]));
    }
    if !v.is_finite() {
        return Err(format!("its value is {v}"));
    }
    Ok(format!("{v}"))
}

/// Numbers, names and the operators, in order.
fn tokens(text: &str) -> Result<Vec<String>, String> {
    let mut out = vec![];
    let mut chars = text.char_indices().peekable();
    while let Some((i, c)) = chars.next() {
        match c {
            c if c.is_whitespace() => {}
            '+' | '-' | '*' | '/' | '(' | ')' => out.push(c.to_string()),
            c if c.is_ascii_alphanumeric() || c == '_' || c == '.' => {
                let mut end = i + c.len_utf8();
                while let Some(&(j, d)) = chars.peek() {
                    // An exponent's sign belongs to its number (`1e-3`).
                    let exponent_sign = (d == '-' || d == '+')
                        && text[i..j].ends_with(['e', 'E'])
                        && text[i..i + 1].chars().all(|c| c.is_ascii_digit() || c == '.');
                    if d.is_ascii_alphanumeric() || d == '_' || d == '.' || exponent_sign {
                        end = j + d.len_utf8();
                        chars.next();
                    } else {
                        break;
                    }
                }
                out.push(text[i..end].to_string());
            }
            other => return Err(format!("`{other}` is no number, parameter or operator (+ - * / and parentheses)")),
        }
    }
    Ok(out)
}

struct Parser<'a> {
    tokens: &'a [String],
    at: usize,
    value_of: &'a dyn Fn(&str) -> Option<String>,
}

impl Parser<'_> {
    fn peek(&self) -> Option<&str> {
        self.tokens.get(self.at).map(String::as_str)
    }

    fn sum(&mut self) -> Result<f64, String> {
        self.left_to_right(["+", "-"], Self::product)
    }

    fn product(&mut self) -> Result<f64, String> {
        self.left_to_right(["*", "/"], Self::factor)
    }

    /// `operand (op operand)*` for the two operators of one precedence, applied left to right.
    fn left_to_right(&mut self, ops: [&str; 2], operand: fn(&mut Self) -> Result<f64, String>) -> Result<f64, String> {
        let mut v = operand(self)?;
        while let Some(op) = self.peek().filter(|t| ops.contains(t)).map(str::to_string) {
            self.at += 1;
            let r = operand(self)?;
            v = match op.as_str() {
                "+" => v + r,
                "-" => v - r,
                "*" => v * r,
                _ => v / r,
            };
        }
        Ok(v)
    }

    fn factor(&mut self) -> Result<f64, String> {
        let token = self.peek().ok_or("it ends where a number or a parameter is expected")?.to_string();
        self.at += 1;
        match token.as_str() {
            "-" => Ok(-self.factor()?),
            "(" => {
                let v = self.sum()?;
                match self.peek() {
                    Some(")") => {
                        self.at += 1;
                        Ok(v)
                    }
                    _ => Err("a `(` without its `)`".into()),
                }
            }
            t if t.starts_with(|c: char| c.is_ascii_digit() || c == '.') => {
                t.parse::<f64>().map_err(|_| format!("`{t}` is not a number"))
            }
            name => {
                let text = (self.value_of)(name).ok_or_else(|| format!("`{name}` names no entry of `[parameters]`"))?;
                text.trim().parse::<f64>().map_err(|_| format!("`{name}` is `{text}`, not a number"))
            }
        }
    }
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
    fn an_arithmetic_placeholder_takes_parameters_and_set_values_with_the_usual_precedence() {
        let text = "[parameters]\nr = 10\nphase = 0\nk = 8\n[b]\nmax = \"${r + phase * 4 / k} mm\"\nt = \"${-(r - 2) * 1e-1}\"\n";
        let out = expand(text, &[]).ok().expect("expands");
        assert!(out.contains("max = \"10 mm\"") && out.contains("t = \"-0.8\""), "{out}");
        let out = expand(text, &[("phase".into(), "-0.4".into())]).ok().expect("expands");
        assert!(out.contains(&format!("max = \"{} mm\"", 10.0 + -0.4 * 4.0 / 8.0)), "{out}");
        for (bad, why) in [
            ("${r + nope}", "`nope` names no entry"),
            ("${r + (phase}", "without its `)`"),
            ("${r + }", "it ends where"),
            ("${r / phase}", "its value is inf"),
            ("${r % 2}", "`%` is no number"),
        ] {
            let e = expand(&text.replace("${-(r - 2) * 1e-1}", bad), &[]).expect_err(bad);
            assert!(e.message.contains(why), "{bad}: {}", e.message);
        }
        let words = "[parameters]\nm = \"models::x\"\n[b]\nx = \"${m + 1}\"\n";
        assert!(expand(words, &[]).expect_err("a word").message.contains("not a number"));
    }

    #[test]
    fn a_text_that_is_not_toml_is_reported_where_it_breaks_not_as_a_missing_parameter() {
        let text = "[parameters]\nv = 1\n[b]\nspeed = \"${v} m/s\"\ntolerance = TOL\n";
        let e = expand(text, &[]).expect_err("an error");
        assert_eq!(&text[e.start..e.start + 3], "TOL", "{}", e.message);
        assert!(!e.message.contains("names no entry"), "{}", e.message);
    }
}
