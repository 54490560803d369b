//! Quantities in case files: a number, or a string with a number and a unit, `"490 MPa"`,
//! `"1000 kg/m^3"`, `"20 us"`. Units take SI prefixes here (unlike in the language, where units
//! are dimensions only); the value is converted to SI.

use crate::units::{Ratio, Unit};

/// A value in SI and its dimension.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantity {
    pub value: f64,
    pub unit: Unit,
}

const PREFIXES: [(&str, f64); 14] = [
    ("G", 1e9),
    ("M", 1e6),
    ("k", 1e3),
    ("h", 1e2),
    ("da", 1e1),
    ("d", 1e-1),
    ("c", 1e-2),
    ("m", 1e-3),
    ("u", 1e-6),
    ("µ", 1e-6),
    ("μ", 1e-6),
    ("n", 1e-9),
    ("p", 1e-12),
    ("T", 1e12),
];

/// A unit name, possibly prefixed: its scale to SI and its dimension.
fn unit_name(name: &str) -> Option<(f64, Unit)> {
    if let Some(u) = Unit::named(name) {
        return Some((1.0, u));
    }
    if name == "g" {
        return Some((1e-3, Unit::KG));
    }
    for (p, scale) in PREFIXES {
        if let Some(rest) = name.strip_prefix(p) {
            if rest == "g" {
                return Some((scale * 1e-3, Unit::KG));
            }
            if rest != "kg" {
                if let Some(u) = Unit::named(rest) {
                    return Some((scale, u));
                }
            }
        }
    }
    None
}

/// Parses a unit expression such as `kg/m^3`, `N*s/m`, `J/kg/K`, `1/s` (a space multiplies).
pub fn parse_unit(text: &str) -> Result<(f64, Unit), String> {
    let text = text.trim();
    if text.is_empty() || text == "-" || text == "1" {
        return Ok((1.0, Unit::ONE));
    }
    let mut scale = 1.0;
    let mut unit = Unit::ONE;
    let mut divide = false;
    let mut token = String::new();
    let flush = |token: &mut String, divide: bool, scale: &mut f64, unit: &mut Unit| -> Result<(), String> {
        if token.is_empty() {
            return Ok(());
        }
        let (name, power) = match token.split_once('^') {
            Some((n, p)) => {
                let p = p.trim_matches(|c| c == '(' || c == ')');
                let r = match p.split_once('/') {
                    Some((a, b)) => {
                        a.parse::<i32>().ok().zip(b.parse::<i32>().ok()).and_then(|(a, b)| Ratio::new(a, b))
                    }
                    None => p.parse::<i32>().ok().map(Ratio::int),
                };
                (n, r.ok_or_else(|| format!("bad exponent `{p}`"))?)
            }
            None => (token.as_str(), Ratio::int(1)),
        };
        let (s, u) = if name == "1" {
            (1.0, Unit::ONE)
        } else {
            unit_name(name).ok_or_else(|| format!("unknown unit `{name}`"))?
        };
        let p = if divide { Ratio::new(-power.num, power.den).unwrap_or(power) } else { power };
        *scale *= s.powf(p.num as f64 / p.den as f64);
        *unit = unit.mul(&u.powr(p).ok_or("unit exponent out of range")?).ok_or("unit exponent out of range")?;
        token.clear();
        Ok(())
    };
    for ch in text.chars() {
        match ch {
            '*' | ' ' | '·' => flush(&mut token, divide, &mut scale, &mut unit)?,
            '/' => {
                flush(&mut token, divide, &mut scale, &mut unit)?;
                divide = true;
            }
            _ => token.push(ch),
        }
        if ch == '*' || ch == '·' {
            divide = false;
        }
    }
    flush(&mut token, divide, &mut scale, &mut unit)?;
    Ok((scale, unit))
}

/// Parses `"490 MPa"`, `"-9.81 m/s^2"`, `"0.3"`.
pub fn parse(text: &str) -> Result<Quantity, String> {
    let text = text.trim();
    let end = number_end(text);
    if end == 0 {
        return Err(format!("expected a number with a unit, like \"490 MPa\", found \"{text}\""));
    }
    let value: f64 = text[..end].parse().map_err(|_| format!("`{}` is not a number", &text[..end]))?;
    let (scale, unit) = parse_unit(&text[end..])?;
    Ok(Quantity { value: value * scale, unit })
}

/// Length of the leading floating-point literal.
fn number_end(s: &str) -> usize {
    let b = s.as_bytes();
    let mut i = 0;
    let digits = |i: &mut usize| {
        let start = *i;
        while *i < b.len() && b[*i].is_ascii_digit() {
            *i += 1;
        }
        *i > start
    };
    if i < b.len() && (b[i] == b'-' || b[i] == b'+') {
        i += 1;
    }
    let int = digits(&mut i);
    let mut frac = false;
    if i < b.len() && b[i] == b'.' {
        i += 1;
        frac = digits(&mut i);
    }
    if !int && !frac {
        return 0;
    }
    if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
        let save = i;
        i += 1;
        if i < b.len() && (b[i] == b'-' || b[i] == b'+') {
            i += 1;
        }
        if !digits(&mut i) {
            i = save;
        }
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::parse_simple;

    #[test]
    fn prefixed_units_convert_to_si() {
        let q = parse("490 MPa").unwrap();
        assert_eq!(q.value, 490e6);
        assert_eq!(q.unit, Unit::named("Pa").unwrap());
        let q = parse("7.85 g/cm^3").unwrap();
        assert!((q.value - 7850.0).abs() < 1e-9);
        assert_eq!(q.unit, parse_simple("kg/m^3").unwrap());
        let q = parse("20 us").unwrap();
        assert!((q.value - 20e-6).abs() < 1e-18);
        let q = parse("4 mm").unwrap();
        assert!((q.value - 0.004).abs() < 1e-15);
        let q = parse("452 J/kg/K").unwrap();
        assert_eq!(q.unit, Unit::named("J").unwrap().div(&Unit::KG).unwrap().div(&Unit::K).unwrap());
        assert_eq!(parse("0.3").unwrap(), Quantity { value: 0.3, unit: Unit::ONE });
        assert_eq!(parse("-9.81 m/s^2").unwrap().value, -9.81);
    }

    #[test]
    fn bad_quantities_say_what_is_wrong() {
        assert!(parse("MPa").unwrap_err().contains("expected a number"));
        assert!(parse("3 furlongs").unwrap_err().contains("unknown unit `furlongs`"));
    }
}
