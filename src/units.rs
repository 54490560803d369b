//! Physical units as dimensions over kg, m, s, K with rational exponents, so that
//! `sqrt(Pa / (kg/m^3))` is m/s. Units carry no scale: the language is SI throughout
//! (case files may write prefixed values such as `490 MPa`; `scene` converts them).

use std::fmt;

/// A rational number p/q in lowest terms, q > 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct Ratio {
    pub num: i32,
    pub den: i32,
}

impl Ratio {
    pub const ZERO: Ratio = Ratio { num: 0, den: 1 };
    pub fn new(num: i32, den: i32) -> Option<Ratio> {
        if den == 0 {
            return None;
        }
        let g = gcd(num.unsigned_abs(), den.unsigned_abs()).max(1) as i32;
        let s = if den < 0 { -1 } else { 1 };
        Some(Ratio { num: s * num / g, den: s * den / g })
    }
    pub fn int(n: i32) -> Ratio {
        Ratio { num: n, den: 1 }
    }
    fn add(self, o: Ratio) -> Option<Ratio> {
        let num = (self.num as i64) * (o.den as i64) + (o.num as i64) * (self.den as i64);
        let den = (self.den as i64) * (o.den as i64);
        narrow(num, den)
    }
    fn mul(self, o: Ratio) -> Option<Ratio> {
        narrow((self.num as i64) * (o.num as i64), (self.den as i64) * (o.den as i64))
    }
    pub fn is_zero(self) -> bool {
        self.num == 0
    }
    /// The ratio nearest to a float, if the float is a simple fraction (denominator ≤ 12).
    pub fn from_f64(x: f64) -> Option<Ratio> {
        (1..=12).find_map(|den| {
            let num = x * den as f64;
            ((num - num.round()).abs() < 1e-9 && num.abs() < 1e6).then(|| Ratio::new(num.round() as i32, den)).flatten()
        })
    }
}

fn narrow(num: i64, den: i64) -> Option<Ratio> {
    let g = gcd64(num.unsigned_abs(), den.unsigned_abs()).max(1) as i64;
    let (n, d) = (num / g, den / g);
    Ratio::new(i32::try_from(n).ok()?, i32::try_from(d).ok()?)
}

fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

fn gcd64(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd64(b, a % b)
    }
}

impl fmt::Display for Ratio {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.den == 1 {
            write!(f, "{}", self.num)
        } else {
            write!(f, "({}/{})", self.num, self.den)
        }
    }
}

pub const BASE_NAMES: [&str; 4] = ["kg", "m", "s", "K"];

/// A physical dimension: exponents of kg, m, s, K.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct Unit(pub [Ratio; 4]);

impl Unit {
    pub const ONE: Unit = Unit([Ratio::ZERO; 4]);
    pub const KG: Unit = Unit::base(0);
    pub const M: Unit = Unit::base(1);
    pub const S: Unit = Unit::base(2);
    pub const K: Unit = Unit::base(3);

    const fn base(i: usize) -> Unit {
        let mut e = [Ratio::ZERO; 4];
        e[i] = Ratio { num: 1, den: 1 };
        Unit(e)
    }
    pub fn is_one(&self) -> bool {
        self.0.iter().all(|r| r.is_zero())
    }
    pub fn mul(&self, o: &Unit) -> Option<Unit> {
        let mut e = [Ratio::ZERO; 4];
        for (k, slot) in e.iter_mut().enumerate() {
            *slot = self.0[k].add(o.0[k])?;
        }
        Some(Unit(e))
    }
    pub fn div(&self, o: &Unit) -> Option<Unit> {
        self.mul(&o.powr(Ratio::int(-1))?)
    }
    pub fn powr(&self, p: Ratio) -> Option<Unit> {
        let mut e = [Ratio::ZERO; 4];
        for (k, slot) in e.iter_mut().enumerate() {
            *slot = self.0[k].mul(p)?;
        }
        Some(Unit(e))
    }
    /// Units of the named derived units and base units the language knows.
    pub fn named(name: &str) -> Option<Unit> {
        let kg = Unit::KG;
        let m = Unit::M;
        let s = Unit::S;
        let n = kg.mul(&m)?.div(&s.powr(Ratio::int(2))?)?;
        Some(match name {
            "kg" => kg,
            "m" => m,
            "s" => s,
            "K" => Unit::K,
            "N" => n,
            "Pa" => n.div(&m.powr(Ratio::int(2))?)?,
            "J" => n.mul(&m)?,
            "W" => n.mul(&m)?.div(&s)?,
            "Hz" => Unit::ONE.div(&s)?,
            "rad" => Unit::ONE,
            _ => return None,
        })
    }
    pub const KNOWN: [&'static str; 10] = ["kg", "m", "s", "K", "N", "Pa", "J", "W", "Hz", "rad"];

    /// The derived unit this is, if it is one of the common ones (for messages).
    /// The unit as a column or axis label: its common name where it has one (`Pa`, `kg/m^3`,
    /// `J/kg`), else its SI base units (`m^2 s^-1`); empty when dimensionless.
    pub fn label(&self) -> String {
        if self.is_one() {
            return String::new();
        }
        if let Some(a) = self.alias().or_else(|| (parse_simple("J/kg").as_ref() == Some(self)).then_some("J/kg")) {
            return a.to_string();
        }
        let text = self.to_string();
        text.split(" (").next().unwrap_or(&text).to_string()
    }

    fn alias(&self) -> Option<&'static str> {
        const ALIASES: [(&str, &str); 9] = [
            ("N", "N"),
            ("Pa", "Pa"),
            ("J", "J"),
            ("W", "W"),
            ("Hz", "1/s"),
            ("kg/m^3", "kg/m^3"),
            ("m/s", "m/s"),
            ("m/s^2", "m/s^2"),
            ("Pa/s", "Pa/s"),
        ];
        ALIASES
            .iter()
            .find_map(|(expr, alias)| (crate::units::parse_simple(expr).as_ref() == Some(self)).then_some(*alias))
    }
}

/// Parses the small unit expressions used internally ("kg/m^3", "Pa/s").
pub fn parse_simple(text: &str) -> Option<Unit> {
    let mut unit = Unit::ONE;
    for (k, part) in text.split('/').enumerate() {
        let (name, pow) = match part.split_once('^') {
            Some((n, p)) => (n, p.parse::<i32>().ok()?),
            None => (part, 1),
        };
        let u = if name == "1" { Unit::ONE } else { Unit::named(name)? }.powr(Ratio::int(pow))?;
        unit = if k == 0 { unit.mul(&u)? } else { unit.div(&u)? };
    }
    Some(unit)
}

impl fmt::Display for Unit {
    /// SI base units with exponents, e.g. `kg m^-1 s^-2 (Pa)`; `1` when dimensionless.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_one() {
            return write!(f, "1 (dimensionless)");
        }
        let mut parts = vec![];
        for (k, e) in self.0.iter().enumerate() {
            if e.is_zero() {
                continue;
            }
            if *e == Ratio::int(1) {
                parts.push(BASE_NAMES[k].to_string());
            } else {
                parts.push(format!("{}^{}", BASE_NAMES[k], e));
            }
        }
        write!(f, "{}", parts.join(" "))?;
        if let Some(a) = self.alias() {
            if !BASE_NAMES.contains(&a) && parts.len() > 1 {
                write!(f, " ({a})")?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqrt_of_pressure_over_density_is_speed() {
        let pa = Unit::named("Pa").unwrap();
        let rho = parse_simple("kg/m^3").unwrap();
        let c = pa.div(&rho).unwrap().powr(Ratio::new(1, 2).unwrap()).unwrap();
        assert_eq!(c, parse_simple("m/s").unwrap());
        assert_eq!(c.to_string(), "m s^-1 (m/s)");
    }

    #[test]
    fn display_of_pascal_names_it() {
        assert_eq!(Unit::named("Pa").unwrap().to_string(), "kg m^-1 s^-2 (Pa)");
        assert_eq!(Unit::ONE.to_string(), "1 (dimensionless)");
        let half = Unit::M.powr(Ratio::new(1, 2).unwrap()).unwrap();
        assert_eq!(half.to_string(), "m^(1/2)");
    }

    #[test]
    fn ratio_from_float_recognises_simple_fractions() {
        assert_eq!(Ratio::from_f64(1.5), Ratio::new(3, 2));
        assert_eq!(Ratio::from_f64(-1.0 / 3.0), Ratio::new(-1, 3));
        assert_eq!(Ratio::from_f64(0.123456), None);
    }
}
