//! The exponential of the CPU backend, written once as a recipe of plain operations so that the
//! lane loops vectorise it (libm's `exp` is a call per lane) and the JIT (`jit.rs`) emits the same
//! operations in the same order: both give bit-identical results, within 1 ulp of the correctly
//! rounded value in f64 and f32.
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

#[cfg(test)]
mod tests {
    use super::*;

    fn ulps64(a: f64, b: f64) -> u64 {
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
            worst = worst.max((exp_f32(x).to_bits() as i64 - exact.to_bits() as i64).unsigned_abs());
            x += 0.00731;
        }
        assert!(worst <= 1, "worst {worst} ulp");
        assert_eq!(exp_f32(100.0), f32::INFINITY);
        assert_eq!(exp_f32(-200.0), 0.0);
        assert!(exp_f32(f32::NAN).is_nan());
    }
}
