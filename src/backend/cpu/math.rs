//! The exponential, logarithm and power of the CPU backend, each written once as a recipe of plain
//! operations so that the lane loops vectorise it (libm's are a call per lane) and the JIT
//! (`jit.rs`) emits the same operations in the same order: both give bit-identical results. exp
//! and ln are within 1 ulp of the correctly rounded value in f64 and f32 (tested below);
//! pow(x, y) = exp(y · ln x) is within (3 |y ln x| + 4) ulp of libm's (tested), the error of
//! ln x and of the product carried by exp.
//!
//! exp(x) = 2^n · p(r), n = round(x / ln 2), r = x − n ln2_hi − n ln2_lo (|r| ≤ ln2/2), p the Taylor
//! polynomial by Horner; the scale 2^n is built from bits as 2^(n+k) · 2^−k with k = ±margin so that
//! subnormal results and results near overflow are each rounded once. x is clamped to a range just
//! wider than where exp is finite and non-zero; NaN passes through (every comparison is false).

/// The constants of the recipe for one precision.
pub struct ExpConsts {
    /// Clamp range of x.
    pub lo: f64,
    pub hi: f64,
    pub log2e: f64,
    /// 1.5 · 2^mantissa: adding it rounds to an integer held in the low bits.
    pub magic: f64,
    pub ln2_hi: f64,
    pub ln2_lo: f64,
    /// Taylor coefficients 1/k!, from k = 0.
    pub coeffs: &'static [f64],
    /// Exponent bias and mantissa width of the format.
    pub bias: i64,
    pub mantissa: u32,
    /// The exponent margin k of the two-step scaling.
    pub margin: i64,
}

const INV_FACT: [f64; 14] = [
    1.0,
    1.0,
    1.0 / 2.0,
    1.0 / 6.0,
    1.0 / 24.0,
    1.0 / 120.0,
    1.0 / 720.0,
    1.0 / 5040.0,
    1.0 / 40320.0,
    1.0 / 362880.0,
    1.0 / 3628800.0,
    1.0 / 39916800.0,
    1.0 / 479001600.0,
    1.0 / 6227020800.0,
];

pub const EXP_F64: ExpConsts = ExpConsts {
    lo: -746.0,
    hi: 710.0,
    log2e: std::f64::consts::LOG2_E,
    magic: 6755399441055744.0,
    // fdlibm's split of ln 2: the high part has trailing zero bits, so n · ln2_hi is exact.
    ln2_hi: f64::from_bits(0x3FE6_2E42_FEE0_0000),
    ln2_lo: f64::from_bits(0x3DEA_39EF_3579_3C76),
    coeffs: &INV_FACT,
    bias: 1023,
    mantissa: 52,
    margin: 64,
};

pub const EXP_F32: ExpConsts = ExpConsts {
    lo: -104.0,
    hi: 89.0,
    log2e: std::f64::consts::LOG2_E,
    magic: 12582912.0,
    ln2_hi: 0.693_359_375,
    ln2_lo: -2.121_944_4e-4,
    coeffs: INV_FACT.split_at(8).0,
    bias: 127,
    mantissa: 23,
    margin: 32,
};

macro_rules! exp_impl {
    ($name:ident, $t:ty, $bits:ty, $consts:expr) => {
        /// The recipe above, branch-free, in this precision.
        #[inline(always)]
        pub fn $name(x: $t) -> $t {
            let k = &$consts;
            let lo = k.lo as $t;
            let hi = k.hi as $t;
            let x = if x < lo {
                lo
            } else if x > hi {
                hi
            } else {
                x
            };
            let magic = k.magic as $t;
            let t = x * (k.log2e as $t) + magic;
            let nf = t - magic;
            let r = x - nf * (k.ln2_hi as $t) - nf * (k.ln2_lo as $t);
            let c = k.coeffs;
            let mut p = c[c.len() - 1] as $t;
            let mut i = c.len() - 1;
            while i > 0 {
                i -= 1;
                p = p * r + c[i] as $t;
            }
            let n = t.to_bits().wrapping_sub(magic.to_bits()) as $bits;
            let m = if x < 0.0 { k.margin as $bits } else { -(k.margin as $bits) };
            let s1 = <$t>::from_bits(((n + m + k.bias as $bits) << k.mantissa) as _);
            let s2 = <$t>::from_bits(((k.bias as $bits - m) << k.mantissa) as _);
            p * s1 * s2
        }
    };
}

exp_impl!(exp_f64, f64, i64, EXP_F64);
exp_impl!(exp_f32, f32, i32, EXP_F32);

/// The constants of the logarithm's recipe for one precision.
///
/// ln(x) for x = 2^k · z, z in [√½, √2): f = z − 1 (exact), s = f / (2 + f), and
/// ln z = f − ½f² + s (½f² + R(s²)) with R fdlibm's minimax polynomial (musl's for f32);
/// k ln 2 is added in two parts. A subnormal x is first scaled by 2^scale. x = 0 gives −∞, +∞
/// gives +∞, a negative x or NaN gives NaN.
pub struct LnConsts {
    /// The mantissa bits of √2: a mantissa above them is halved (k one larger).
    pub sqrt2_mantissa: i64,
    pub ln2_hi: f64,
    pub ln2_lo: f64,
    /// R(w) = w · (lg[0] + w · (lg[1] + …)).
    pub lg: &'static [f64],
    pub bias: i64,
    pub mantissa: u32,
    /// The smallest normal number, and the power of two a smaller x is scaled by.
    pub min_normal: f64,
    pub scale: i64,
}

pub const LN_F64: LnConsts = LnConsts {
    sqrt2_mantissa: 0x6_A09E_667F_3BCD,
    ln2_hi: f64::from_bits(0x3FE6_2E42_FEE0_0000),
    ln2_lo: f64::from_bits(0x3DEA_39EF_3579_3C76),
    // fdlibm's Lg1 … Lg7.
    lg: &[
        f64::from_bits(0x3FE5_5555_5555_5593),
        f64::from_bits(0x3FD9_9999_9997_FA04),
        f64::from_bits(0x3FD2_4924_9422_9359),
        f64::from_bits(0x3FCC_71C5_1D8E_78AF),
        f64::from_bits(0x3FC7_4664_96CB_03DE),
        f64::from_bits(0x3FC3_9A09_D078_C69F),
        f64::from_bits(0x3FC2_F112_DF3E_5244),
    ],
    bias: 1023,
    mantissa: 52,
    min_normal: f64::MIN_POSITIVE,
    scale: 54,
};

pub const LN_F32: LnConsts = LnConsts {
    sqrt2_mantissa: 0x35_04F3,
    // musl's logf: 0x3f317180, 0x3717f7d1.
    ln2_hi: f32::from_bits(0x3f31_7180) as f64,
    ln2_lo: f32::from_bits(0x3717_f7d1) as f64,
    // musl's logf: 0xaaaaaa.0p-24, 0xccce13.0p-25, 0x91e9ee.0p-25, 0xf89e26.0p-26.
    lg: &[
        0xaa_aaaa as f64 / (1u64 << 24) as f64,
        0xcc_ce13 as f64 / (1u64 << 25) as f64,
        0x91_e9ee as f64 / (1u64 << 25) as f64,
        0xf8_9e26 as f64 / (1u64 << 26) as f64,
    ],
    bias: 127,
    mantissa: 23,
    min_normal: f32::MIN_POSITIVE as f64,
    scale: 25,
};

macro_rules! ln_impl {
    ($name:ident, $pow:ident, $exp:ident, $t:ty, $bits:ty, $ubits:ty, $consts:expr) => {
        /// The logarithm's recipe above, branch-free, in this precision.
        #[inline(always)]
        pub fn $name(x: $t) -> $t {
            let k = &$consts;
            let tiny = x < k.min_normal as $t;
            let xs = if tiny { x * (2.0 as $t).powi(k.scale as i32) } else { x };
            let bits = xs.to_bits() as $bits;
            let e = ((bits as $ubits) >> k.mantissa) as $bits;
            let mant = bits & (((1 as $bits) << k.mantissa) - 1);
            let big = if mant > k.sqrt2_mantissa as $bits { 1 } else { 0 };
            let z = <$t>::from_bits((mant | ((k.bias as $bits - big) << k.mantissa)) as _);
            let n = e - k.bias as $bits + big - if tiny { k.scale as $bits } else { 0 };
            let f = z - 1.0;
            let s = f / (2.0 + f);
            let w = s * s;
            let lg = k.lg;
            let mut r = lg[lg.len() - 1] as $t;
            for c in lg[..lg.len() - 1].iter().rev() {
                r = r * w + *c as $t;
            }
            let r = r * w;
            let hfsq = 0.5 * f * f;
            let nf = n as $t;
            let y = nf * k.ln2_hi as $t - ((hfsq - (s * (hfsq + r) + nf * k.ln2_lo as $t)) - f);
            let y = if x == 0.0 { <$t>::NEG_INFINITY } else { y };
            let y = if x == <$t>::INFINITY { <$t>::INFINITY } else { y };
            if x < 0.0 || x.is_nan() {
                <$t>::NAN
            } else {
                y
            }
        }

        /// x^y = exp(y · ln x), 1 where y = 0 or x = 1; NaN for a negative x.
        #[inline(always)]
        pub fn $pow(x: $t, y: $t) -> $t {
            let p = $exp(y * $name(x));
            if y == 0.0 || x == 1.0 {
                1.0
            } else {
                p
            }
        }
    };
}

ln_impl!(ln_f64, pow_f64, exp_f64, f64, i64, u64, LN_F64);
ln_impl!(ln_f32, pow_f32, exp_f32, f32, i32, u32, LN_F32);

#[cfg(test)]
mod tests {
    use super::*;

    fn ulps64(a: f64, b: f64) -> u64 {
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs()
    }

    fn ulps32(a: f32, b: f32) -> u64 {
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs()
    }

    #[test]
    fn exp_f64_is_within_one_ulp_of_libm_over_its_range() {
        let mut worst = 0;
        let mut x = -745.0;
        while x < 709.7 {
            worst = worst.max(ulps64(exp_f64(x), x.exp()));
            x += 0.0137;
        }
        for x in [-1e-300, 0.0, 1e-20, -0.5, 0.5, -9.0, 3.0] {
            worst = worst.max(ulps64(exp_f64(x), x.exp()));
        }
        assert!(worst <= 1, "worst {worst} ulp");
        assert_eq!(exp_f64(0.0), 1.0);
        assert_eq!(exp_f64(1000.0), f64::INFINITY);
        assert_eq!(exp_f64(-1000.0), 0.0);
        assert_eq!(exp_f64(f64::INFINITY), f64::INFINITY);
        assert_eq!(exp_f64(f64::NEG_INFINITY), 0.0);
        assert!(exp_f64(f64::NAN).is_nan());
        // Subnormal results, rounded once.
        assert!(ulps64(exp_f64(-740.0), (-740.0f64).exp()) <= 1);
    }

    #[test]
    fn exp_f32_is_within_one_ulp_of_the_f64_value() {
        let mut worst = 0;
        let mut x = -87.0f32;
        while x < 88.7 {
            let exact = (x as f64).exp() as f32;
            worst = worst.max(ulps32(exp_f32(x), exact));
            x += 0.00731;
        }
        assert!(worst <= 1, "worst {worst} ulp");
        assert_eq!(exp_f32(100.0), f32::INFINITY);
        assert_eq!(exp_f32(-200.0), 0.0);
        assert!(exp_f32(f32::NAN).is_nan());
    }

    #[test]
    fn ln_f64_is_within_one_ulp_of_libm() {
        let mut worst = 0;
        let mut x = 1e-300f64;
        while x < 1e300 {
            worst = worst.max(ulps64(ln_f64(x), x.ln()));
            x *= 1.0137;
        }
        let mut x = 0.5f64;
        while x < 2.0 {
            worst = worst.max(ulps64(ln_f64(x), x.ln()));
            x += 1.3e-4;
        }
        for x in [5e-324, 1e-310, 2.2250738585072014e-308, f64::MAX, 1.0 + 1e-15, 1.0 - 1e-16] {
            worst = worst.max(ulps64(ln_f64(x), x.ln()));
        }
        assert!(worst <= 1, "worst {worst} ulp");
        assert_eq!(ln_f64(1.0), 0.0);
        assert_eq!(ln_f64(0.0), f64::NEG_INFINITY);
        assert_eq!(ln_f64(f64::INFINITY), f64::INFINITY);
        assert!(ln_f64(-1.0).is_nan() && ln_f64(f64::NAN).is_nan());
    }

    #[test]
    fn ln_f32_is_within_one_ulp_of_the_f64_value() {
        let mut worst = 0;
        let mut x = 1.2e-38f32;
        while x < 3e38 {
            let exact = (x as f64).ln() as f32;
            worst = worst.max(ulps32(ln_f32(x), exact));
            x *= 1.00731;
        }
        let mut x = 0.5f32;
        while x < 2.0 {
            let exact = (x as f64).ln() as f32;
            worst = worst.max(ulps32(ln_f32(x), exact));
            x += 1.7e-5;
        }
        for x in [1e-45f32, 3e-42, 1.1e-38, f32::MAX] {
            let exact = (x as f64).ln() as f32;
            worst = worst.max(ulps32(ln_f32(x), exact));
        }
        assert!(worst <= 1, "worst {worst} ulp");
        assert_eq!(ln_f32(0.0), f32::NEG_INFINITY);
        assert!(ln_f32(-2.0).is_nan());
    }

    #[test]
    fn pow_is_within_its_bound_of_libm_and_exact_at_its_special_values() {
        // |pow − libm| ≤ (3 |y ln x| + 4) ulp of the result: ln's ulp and the product's rounding,
        // carried by exp, relative to the ulp of the result.
        let mut worst = 0.0f64;
        for i in 0..4000 {
            let x = 1e-6 * 1.0093f64.powi(i);
            for y in [1.0 / 7.0, 0.26, -0.5, 2.5, 7.0, -3.3, 0.001] {
                let (p, q) = (pow_f64(x, y), x.powf(y));
                let bound = 3.0 * (y * x.ln()).abs() + 4.0;
                worst = worst.max(ulps64(p, q) as f64 / bound);
            }
        }
        assert!(worst <= 1.0, "worst {worst} of the bound");
        assert_eq!(pow_f64(0.0, 0.0), 1.0);
        assert_eq!(pow_f64(1.0, f64::NAN), 1.0);
        assert_eq!(pow_f64(0.0, 2.5), 0.0);
        assert_eq!(pow_f64(0.0, -2.5), f64::INFINITY);
        assert_eq!(pow_f64(4.0, 0.5), 2.0);
        assert!(pow_f64(-8.0, 1.0 / 3.0).is_nan());
        assert_eq!(pow_f32(1.0, 3.7), 1.0);
        assert!((pow_f32(1.001, 1.0 / 7.0) as f64 - 1.001f64.powf(1.0 / 7.0)).abs() < 2e-7);
    }
}
