//! Mutations of TOML files (case and study files). On the parsed tree: a value replaced by one of
//! another type or an extreme number, a key deleted, renamed or given another file's value, an
//! array element (a `[[bodies]]` or `[[runs]]` table) deleted or duplicated, a quantity's number
//! or unit changed. On the text: numbers replaced, quotes broken, `${…}` placeholders inserted,
//! tables duplicated or their headers changed, lines spliced from other files, and every edit of
//! [`super::text::mutate_text`].

use super::text::{mutate_text, replace_number, NUMBERS};
use super::Rng;

/// Values of every TOML type, extreme ones included, written as TOML.
pub const VALUES: &[&str] = &[
    "0",
    "-1",
    "1",
    "2",
    "3",
    "0.3",
    "1e-9",
    "1e-300",
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "9223372036854775807",
    "-9223372036854775808",
    "true",
    "false",
    "\"\"",
    "\"abc\"",
    "\"0\"",
    "\"1e-9 m\"",
    "\"1e-12 m\"",
    "\"1e6 m\"",
    "\"1000 km\"",
    "\"-5 mm\"",
    "\"5 mm\"",
    "\"0 m\"",
    "\"nan m\"",
    "\"inf s\"",
    "\"1 us\"",
    "\"1e-30 s\"",
    "\"1e30 s\"",
    "\"100 m/s\"",
    "\"1e300 m/s\"",
    "\"7850 kg/m^3\"",
    "\"200 GPa\"",
    "\"1 m^99999\"",
    "\"1 m^(1/0)\"",
    "\"1 m^(-2147483648/3)\"",
    "\"5 mm mm\"",
    "\"1 [m]\"",
    "\"${v}\"",
    "\"${nope}\"",
    "\"${\"",
    "\"ci\"",
    "\"paper\"",
    "\"ci@2mm\"",
    "\"ci@nan\"",
    "\"@\"",
    "\"cells\"",
    "\"verlet\"",
    "\"adaptive\"",
    "\"eps_p\"",
    "\"x\"",
    "\"z\"",
    "\"xy\"",
    "\"norm\"",
    "\"von_mises\"",
    "\"nodes\"",
    "\"models::elastic_solid\"",
    "\"models::nope\"",
    "\"models::../../Cargo\"",
    "\"/dev/zero\"",
    "\"/\"",
    "\".\"",
    "\"../cases/cantilever.toml\"",
    "\"rings_2d.sph\"",
    "\"nodes_plate.csv\"",
    "\"nodes_plate.k\"",
    "\"x * (1 [m] - x.x)\"",
    "\"rho0 * (1 + 1e-4 [1/m] * x.y)\"",
    "\"((((((((((((((((((((((((((((((((((((((((1))))))))))))))))))))))))))))))))))))))))\"",
    "\"\\u00e9 \\t \\\" x\"",
    "'literal ${v}'",
    "\"\"\"\nmulti\nline\"\"\"",
    "[]",
    "[0]",
    "[0, 0]",
    "[0, 0, 0]",
    "[0, 0, 0, 0]",
    "[1, 2, 3]",
    "[\"1 mm\", \"2 mm\", \"3 mm\"]",
    "[\"-1e6 m\", 0, \"1e6 m\"]",
    "[[0, 0], [1, 0], [0, 1]]",
    "[[0, 0], [1, 1], [1, 0], [0, 1]]",
    "[nan, nan, nan]",
    "[\"a\", 1, true]",
    "{}",
    "{ a = 1 }",
    "{ box = { min = [0, 0, 0], max = [1, 1, 1] } }",
    "{ box = { min = [\"-1e6 m\", \"-1e6 m\", \"-1e6 m\"], max = [\"1e6 m\", \"1e6 m\", \"1e6 m\"] } }",
    "{ sphere = { center = [0, 0, 0], radius = \"1e-9 m\" } }",
    "{ sphere = { center = [0, 0, 0], radius = 1e300 } }",
    "{ cylinder = { base = [0, 0, 0], axis = [1, 1, 1], radius = 0.01, length = 1e-12 } }",
    "{ nodes = { file = \"nodes_plate.csv\", scale = 1e-300 } }",
    "{ nodes = { file = \"/dev/zero\" } }",
    "{ polygon = { vertices = [[0, 0], [1, 1], [1, 0], [0, 1]] } }",
    "{ dx = \"1e-9 m\" }",
    "{ dx = \"1 mm\", set = { nope = 1 } }",
    "{ dx = \"1 mm\", time_scale = 0 }",
    "{ factor = 1e-9, region = { sphere = { center = [0, 0, 0], radius = 1 } } }",
    "{ center = [0, 0, 0], omega = \"1e300 rad/s\", axis = [0, 0, 0] }",
    "1979-05-27T07:32:00Z",
    "07:32:00",
];

/// The path to a value in a tree: keys of tables and indices of arrays.
#[derive(Clone, Debug)]
enum Step {
    Key(String),
    Index(usize),
}

fn paths(v: &toml::Value, here: &mut Vec<Step>, out: &mut Vec<Vec<Step>>) {
    match v {
        toml::Value::Table(t) => {
            for (k, x) in t {
                here.push(Step::Key(k.clone()));
                out.push(here.clone());
                paths(x, here, out);
                here.pop();
            }
        }
        toml::Value::Array(a) => {
            for (k, x) in a.iter().enumerate() {
                here.push(Step::Index(k));
                out.push(here.clone());
                paths(x, here, out);
                here.pop();
            }
        }
        _ => {}
    }
}

fn at_mut<'a>(v: &'a mut toml::Value, path: &[Step]) -> Option<&'a mut toml::Value> {
    let mut v = v;
    for s in path {
        v = match (s, v) {
            (Step::Key(k), toml::Value::Table(t)) => t.get_mut(k)?,
            (Step::Index(i), toml::Value::Array(a)) => a.get_mut(*i)?,
            _ => return None,
        };
    }
    Some(v)
}

fn at<'a>(v: &'a toml::Value, path: &[Step]) -> Option<&'a toml::Value> {
    let mut v = v;
    for s in path {
        v = match (s, v) {
            (Step::Key(k), toml::Value::Table(t)) => t.get(k)?,
            (Step::Index(i), toml::Value::Array(a)) => a.get(*i)?,
            _ => return None,
        };
    }
    Some(v)
}

/// One of [`VALUES`] as a TOML value.
fn value(rng: &mut Rng) -> toml::Value {
    let text = format!("v = {}", rng.word(VALUES));
    toml::from_str::<toml::Table>(&text).ok().and_then(|mut t| t.remove("v")).unwrap_or(toml::Value::Integer(0))
}

/// A quantity string with an interesting number or unit: `"1e-9 mm"`, `"5 Pa"`.
fn quantity(rng: &mut Rng, old: &str) -> String {
    const UNITS: &[&str] =
        &["m", "mm", "um", "km", "s", "us", "ms", "m/s", "Pa", "GPa", "kg/m^3", "rad/s", "N", "J/kg/K", "", "K", "1/s"];
    let mut parts = old.splitn(2, ' ');
    let (num, unit) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    if rng.chance(60) {
        format!("{} {unit}", rng.word(NUMBERS))
    } else {
        format!("{num} {}", rng.word(UNITS))
    }
}

/// One edit of the parsed tree; `other` is another file's tree (keys and values to splice in).
fn mutate_tree(rng: &mut Rng, root: &mut toml::Value, other: &toml::Value) {
    let mut all = vec![];
    paths(root, &mut vec![], &mut all);
    if all.is_empty() {
        return;
    }
    let path = rng.pick(&all).clone();
    let (parent, last) = path.split_at(path.len() - 1);
    // Strings of this file: names of bodies, materials, probes, fields to mix up.
    let strings: Vec<String> =
        all.iter().filter_map(|p| at(root, p).and_then(|v| v.as_str()).map(str::to_string)).collect();
    match rng.below(16) {
        0 | 1 => {
            if let Some(v) = at_mut(root, &path) {
                *v = value(rng);
            }
        }
        2..=9 => {
            // Changed in place, keeping its type: a number, a quantity's number or unit, a name.
            if let Some(v) = at_mut(root, &path) {
                match v {
                    toml::Value::String(s) if s.contains(' ') || rng.chance(30) => *s = quantity(rng, s),
                    toml::Value::String(s) => {
                        *s = match rng.below(3) {
                            0 if !strings.is_empty() => rng.pick(&strings).clone(),
                            1 => format!("{s}x"),
                            _ => s.chars().rev().collect(),
                        }
                    }
                    toml::Value::Integer(_) | toml::Value::Float(_) => {
                        let t = format!("v = {}", rng.word(NUMBERS));
                        if let Some(x) = toml::from_str::<toml::Table>(&t).ok().and_then(|mut t| t.remove("v")) {
                            *v = x;
                        }
                    }
                    toml::Value::Boolean(b) => *b = !*b,
                    _ => *v = value(rng),
                }
            }
        }
        10 => {
            // Deleted.
            if let Some(p) = at_mut(root, parent) {
                match (p, &last[0]) {
                    (toml::Value::Table(t), Step::Key(k)) => {
                        t.remove(k);
                    }
                    (toml::Value::Array(a), Step::Index(i)) if *i < a.len() => {
                        a.remove(*i);
                    }
                    _ => {}
                }
            }
        }
        11 => {
            // Duplicated (an array element: another body, run, probe), or renamed (a key).
            if let Some(p) = at_mut(root, parent) {
                match (p, &last[0]) {
                    (toml::Value::Table(t), Step::Key(k)) => {
                        if let Some(v) = t.get(k).cloned() {
                            let mut name = k.clone();
                            match rng.below(3) {
                                0 => name.push('s'),
                                1 => {
                                    name.pop();
                                }
                                _ => name = name.to_uppercase(),
                            }
                            t.insert(name, v);
                        }
                    }
                    (toml::Value::Array(a), Step::Index(i)) if *i < a.len() => {
                        let v = a[*i].clone();
                        for _ in 0..1 + rng.below(3) {
                            a.insert(*i, v.clone());
                        }
                    }
                    _ => {}
                }
            }
        }
        12 => {
            // Another file's key and value, put into a table of this one.
            let mut theirs = vec![];
            paths(other, &mut vec![], &mut theirs);
            if theirs.is_empty() {
                return;
            }
            let src = rng.pick(&theirs).clone();
            let Some(v) = at(other, &src).cloned() else { return };
            let key = match src.last() {
                Some(Step::Key(k)) => k.clone(),
                _ => "extra".into(),
            };
            let mut tables = vec![vec![]];
            tables.extend(all.iter().filter(|p| matches!(at(root, p), Some(toml::Value::Table(_)))).cloned());
            let to = rng.pick(&tables).clone();
            if let Some(toml::Value::Table(t)) = at_mut(root, &to) {
                t.insert(key, v);
            }
        }
        13 | 14 => {
            // Two values swapped.
            let other_path = rng.pick(&all).clone();
            let (a, b) = (at(root, &path).cloned(), at(root, &other_path).cloned());
            if let (Some(a), Some(b)) = (a, b) {
                if let Some(x) = at_mut(root, &path) {
                    *x = b;
                }
                if let Some(x) = at_mut(root, &other_path) {
                    *x = a;
                }
            }
        }
        _ => {
            // A value wrapped: a scalar becomes a list, a list a table.
            if let Some(v) = at_mut(root, &path) {
                let inner = v.clone();
                *v = if rng.chance(50) {
                    toml::Value::Array(vec![inner.clone(), inner])
                } else {
                    let mut t = toml::Table::new();
                    t.insert("box".into(), inner);
                    toml::Value::Table(t)
                };
            }
        }
    }
}

/// The text with each placeholder that stands for a value (`C_cfl = ${cfl}`, not inside a
/// string) made a string `"@@${cfl}@@"`, so that it parses as TOML; undone after serialising.
fn protect(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(k) = rest.find("${") {
        let before = rest[..k].trim_end_matches([' ', '\t']);
        let bare = before.ends_with(['=', '[', ',', '{']);
        let close = rest[k..].find('}').map(|c| k + c + 1);
        match close {
            Some(c) if bare && !rest[k..c].contains('\n') => {
                out.push_str(&rest[..k]);
                out.push_str("\"@@");
                out.push_str(&rest[k..c]);
                out.push_str("@@\"");
                rest = &rest[c..];
            }
            _ => {
                out.push_str(&rest[..k + 2]);
                rest = &rest[k + 2..];
            }
        }
    }
    out.push_str(rest);
    out
}

/// Placeholders, broken and whole.
const PLACEHOLDERS: &[&str] = &["${v}", "${nope}", "${", "$}", "${}", "${${v}}", "${v", "$", "${ v }", "${é}"];

/// One edit of a TOML file's text (`others`: other files of the kind, for splices).
pub fn mutate(rng: &mut Rng, text: &mut String, others: &[String]) {
    let other = rng.pick(others);
    match rng.below(20) {
        0..=13 => {
            // On the tree, when the text parses (placeholders standing for values made strings).
            let (Ok(mut tree), Ok(theirs)) =
                (protect(text).parse::<toml::Table>(), protect(other).parse::<toml::Table>())
            else {
                mutate_text(rng, text, other);
                return;
            };
            let mut root = toml::Value::Table(std::mem::take(&mut tree));
            for _ in 0..1 + rng.below(2) {
                mutate_tree(rng, &mut root, &toml::Value::Table(theirs.clone()));
            }
            if let toml::Value::Table(t) = root {
                if let Ok(s) = toml::to_string(&t) {
                    *text = s.replace("\"@@${", "${").replace("}@@\"", "}");
                }
            }
        }
        14 => {
            let with = rng.word(NUMBERS);
            replace_number(rng, text, with);
        }
        15 => {
            // A quote removed or added.
            let quotes: Vec<usize> = text.match_indices('"').map(|(k, _)| k).collect();
            if !quotes.is_empty() && rng.chance(70) {
                text.remove(*rng.pick(&quotes));
            } else {
                let ends: Vec<usize> = text.match_indices('\n').map(|(k, _)| k).collect();
                if !ends.is_empty() {
                    text.insert(*rng.pick(&ends), '"');
                }
            }
        }
        16 => {
            // A placeholder, inside a string or as a bare value.
            let quotes: Vec<usize> = text.match_indices('"').map(|(k, _)| k + 1).collect();
            let p = rng.word(PLACEHOLDERS);
            let values: Vec<usize> = text.match_indices(" = ").map(|(k, _)| k + 3).collect();
            if !quotes.is_empty() && (values.is_empty() || rng.chance(70)) {
                text.insert_str(*rng.pick(&quotes), p);
            } else if !values.is_empty() {
                let at = *rng.pick(&values);
                let line_end = text[at..].find('\n').map_or(text.len(), |n| at + n);
                text.replace_range(at..line_end, p);
            }
        }
        17 => {
            // A table header changed: `[[bodies]]` ↔ `[bodies]`, or another table's name.
            let headers: Vec<(usize, usize)> = text
                .match_indices('\n')
                .map(|(k, _)| k + 1)
                .chain([0])
                .filter(|k| text[*k..].starts_with('['))
                .map(|k| (k, text[k..].find('\n').map_or(text.len(), |n| k + n)))
                .collect();
            if headers.is_empty() {
                mutate_text(rng, text, other);
                return;
            }
            let (a, b) = *rng.pick(&headers);
            let h = text[a..b].to_string();
            let new = match rng.below(4) {
                0 if h.starts_with("[[") => h.replacen("[[", "[", 1).replacen("]]", "]", 1),
                0 => h.replacen('[', "[[", 1).replacen(']', "]]", 1),
                1 => rng
                    .word(&[
                        "[[bodies]]",
                        "[[runs]]",
                        "[neighbours]",
                        "[parameters]",
                        "[resolutions]",
                        "[output]",
                        "[[probes]]",
                        "[[results]]",
                        "[[constraints]]",
                        "[[loads]]",
                        "[[symmetry]]",
                        "[materials.steel]",
                        "[materials]",
                        "[bodies]",
                    ])
                    .to_string(),
                2 => String::new(),
                _ => format!("{h}\n{h}"),
            };
            text.replace_range(a..b, &new);
        }
        18 => {
            // A whole table duplicated (same key twice, or another array element).
            let starts: Vec<usize> = text.match_indices("\n[").map(|(k, _)| k + 1).collect();
            if starts.is_empty() {
                mutate_text(rng, text, other);
                return;
            }
            let a = *rng.pick(&starts);
            let b = text[a + 1..].find("\n[").map_or(text.len(), |n| a + 1 + n + 1);
            let block = text[a..b].to_string();
            text.insert_str(a, &block);
        }
        19 if rng.chance(50) => {
            // A string's content replaced.
            let quotes: Vec<usize> = text.match_indices('"').map(|(k, _)| k).collect();
            if quotes.len() >= 2 {
                let i = rng.below(quotes.len() - 1);
                let (a, b) = (quotes[i] + 1, quotes[i + 1]);
                if !text[a..b].contains('\n') {
                    let old = text[a..b].to_string();
                    let new = if rng.chance(50) {
                        quantity(rng, &old)
                    } else {
                        rng.word(VALUES).trim_matches('"').to_string()
                    };
                    text.replace_range(a..b, &new);
                }
            }
        }
        _ => mutate_text(rng, text, other),
    }
}
