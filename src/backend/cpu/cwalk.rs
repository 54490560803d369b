//! The neighbour walk in C. A particle's candidates (a kept list's entries, or a cell range of the
//! grid's order) become the batch's lanes (x_ij, r_ij, h_ij and j of each candidate within the
//! cut-off, in order) as `exec::offer_candidate` writes them one at a time, but four f64 or eight
//! f32 candidates at once: their distances as one vector, one square root, and the kept lanes
//! packed to the front by a permutation (AVX2). The scalar walk spent a third of the dam break's
//! step on one candidate's chain of loads, distance, root and store after another.
//!
//! The lanes below the batch's count are the scalar walk's bit for bit (the same operations on
//! each candidate, `-ffp-contract=off`), and the walk stops where the scalar walk flushes (the
//! batch full), taking four (eight) candidates at a time only while they fit the batch: the
//! batches, and so the sums, do not change. One call walks one image transform's candidates (a
//! run of a list, or a cell range, with that transform's position of i and signs). Compiled once
//! per precision and dimension by the machine's C compiler and cached as the pair programs are
//! ([`super::ccode`]); without one the scalar walk runs.

use super::ccode;
use super::lists::INDEX_MASK;
use super::program::LANES;
use crate::particles::Real;
use std::sync::OnceLock;

/// `walk(list, count, x, h, group, sources, yi, flip, hi, support, frame, x_reg, r_reg, h_reg, j,
/// sign, n)`: adds the candidates `list` names (particle indices, with one image transform's bits
/// above them or none) from the first to the batch at lane `*n`, until the list ends or the batch
/// is full; returns how many it took. `yi` is particle i or its image, `flip` the image's ±1 per
/// axis (x_ij's components are multiplied by them and, where `sign` is not null, they are the
/// lanes' signs).
pub(super) type WalkFn<T> = unsafe extern "C" fn(
    *const u32,
    usize,
    *const T,
    *const T,
    *const u32,
    u64,
    *const T,
    *const T,
    T,
    T,
    *mut T,
    usize,
    usize,
    usize,
    *mut u32,
    *mut T,
    *mut usize,
) -> usize;

/// The compiled walk for `T` in `dim` dimensions, compiled on first use; `None` where no C
/// compiler answers (or the C path is off on this thread).
pub(super) fn walker<T: Real>(dim: usize) -> Option<WalkFn<T>> {
    /// Per precision (f32, f64) and dimension: the function, as an address (its library is
    /// kept loaded for the process).
    static WALKS: [[OnceLock<Option<usize>>; 3]; 2] = [const { [const { OnceLock::new() }; 3] }; 2];
    if !ccode::enabled() || !(1..=3).contains(&dim) {
        return None;
    }
    let slot = &WALKS[(T::BYTES == 8) as usize][dim - 1];
    let address = slot.get_or_init(|| match compile::<T>(dim) {
        Ok(a) => Some(a),
        Err(e) => {
            if crate::config::env().debug >= 1 {
                eprintln!("the neighbour walk in C: {e}; the scalar walk runs");
            }
            None
        }
    });
    let address = (*address)?;
    // SAFETY: the address of `walk`, printed with exactly this signature for this T (its
    // precision indexes the slot), in a library never unloaded.
    Some(unsafe { std::mem::transmute::<usize, WalkFn<T>>(address) })
}

fn compile<T: Real>(dim: usize) -> Result<usize, String> {
    let lib = ccode::build_source(&source::<T>(dim))?;
    // SAFETY: `walk` was printed with the signature of `WalkFn`.
    let address = unsafe {
        let sym: libloading::Symbol<WalkFn<T>> = lib.get(b"walk\0").map_err(|e| e.to_string())?;
        *sym as usize
    };
    // The function lives as long as the process.
    std::mem::forget(lib);
    Ok(address)
}

/// The permutation that packs the kept lanes of a vector to its front, per mask of kept lanes, as
/// indices of 32-bit lanes (an f64 lane is two).
fn pack_table(lanes: usize) -> String {
    let per = 8 / lanes;
    let rows: Vec<String> = (0..1usize << lanes)
        .map(|mask| {
            let kept: Vec<usize> = (0..lanes).filter(|k| mask >> k & 1 == 1).collect();
            let idx: Vec<String> = (0..8)
                .map(|p| {
                    let (lane, half) = (p / per, p % per);
                    kept.get(lane).map_or(0, |k| k * per + half).to_string()
                })
                .collect();
            format!("{{{}}}", idx.join(", "))
        })
        .collect();
    format!("static const int PACK[{}][8] = {{\n    {}\n}};", 1usize << lanes, rows.join(",\n    "))
}

/// The C source of the walk for `T` in `dim` dimensions.
fn source<T: Real>(dim: usize) -> String {
    let f64 = T::BYTES == 8;
    let lanes = 32 / T::BYTES;
    let (r, v, ps, sqrt) = if f64 { ("double", "__m256d", "pd", "sqrt") } else { ("float", "__m256", "ps", "sqrtf") };
    // A vector of the entries' component c: set in reverse lane order.
    let gather = |of: &str| -> String {
        let lanes: Vec<String> = (0..lanes).rev().map(|k| of.replace("{k}", &k.to_string())).collect();
        format!("_mm256_set_{ps}({})", lanes.join(", "))
    };
    let mut vector = String::new();
    for k in 0..lanes {
        vector += &format!("        const size_t j{k} = list[i + {k}] & INDEX_MASK;\n");
    }
    vector += "        V r2 = zero;\n";
    for c in 0..dim {
        let xs = gather(&format!("x[j{{k}} * D + {c}]"));
        vector += &format!("        const V d{c} = y{c} - {xs};\n        r2 = r2 + d{c} * d{c};\n");
        vector += &format!("        const V dx{c} = d{c} * f{c};\n");
    }
    vector += &format!("        const V hij = (vhi + {}) * half;\n", gather("h[j{k}]"));
    vector += "        const V rc = vsupport * hij;\n";
    vector += &format!(
        "        int mask = _mm256_movemask_{ps}(_mm256_and_{ps}(_mm256_cmp_{ps}(r2, rc * rc, _CMP_LT_OQ), \
         _mm256_cmp_{ps}(r2, zero, _CMP_NEQ_UQ)));\n"
    );
    let from: Vec<String> = (0..lanes).map(|k| format!("(int)((sources >> group[j{k}]) & 1) << {k}")).collect();
    vector += &format!("        if (~sources) mask &= {};\n", from.join(" | "));
    vector += "        const __m256i pack = _mm256_loadu_si256((const __m256i *)PACK[mask]);\n";
    let store = |reg: &str, value: &str| -> String {
        if f64 {
            format!(
                "        _mm256_storeu_pd(frame + ({reg}) * LANES + n, \
                 _mm256_castps_pd(_mm256_permutevar8x32_ps(_mm256_castpd_ps({value}), pack)));\n"
            )
        } else {
            format!("        _mm256_storeu_ps(frame + ({reg}) * LANES + n, _mm256_permutevar8x32_ps({value}, pack));\n")
        }
    };
    for c in 0..dim {
        vector += &store(&format!("x_reg + {c}"), &format!("dx{c}"));
    }
    vector += &format!(
        "        if (sign) for (int c = 0; c < 3; c++) _mm256_storeu_{ps}(sign + c * LANES + n, _mm256_set1_{ps}(flip[c]));\n"
    );
    vector += &store("r_reg", &format!("_mm256_sqrt_{ps}(r2)"));
    vector += &store("h_reg", "hij");
    for k in 0..lanes {
        vector += &format!("        jout[n] = (unsigned)j{k};\n        n += (mask >> {k}) & 1;\n");
    }
    let ys: String = (0..dim)
        .map(|c| format!("    const V y{c} = _mm256_set1_{ps}(yi[{c}]), f{c} = _mm256_set1_{ps}(flip[{c}]);\n"))
        .collect();
    format!(
        r#"/* generated by pairsum: the neighbour walk (backend/cpu/cwalk.rs) */
#include <stddef.h>
#include <math.h>
#if defined(__AVX2__)
#include <immintrin.h>
#endif
typedef {r} R;
enum {{ D = {dim}, LANES = {LANES}, W = {lanes} }};
#define INDEX_MASK {mask}u

/* One candidate, as exec::offer_candidate and Writer::offer write it (x_ij = flip · (y_i − x_j):
   the sign change is exact). */
static inline size_t one(unsigned e, const R *x, const R *h, const unsigned *group, unsigned long long sources,
                         const R *yi, const R *flip, R hi, R support, R *frame, size_t x_reg, size_t r_reg,
                         size_t h_reg, unsigned *jout, R *sign, size_t n) {{
    const size_t j = e & INDEX_MASK;
    R r2 = 0;
    for (int c = 0; c < D; c++) {{
        const R diff = yi[c] - x[j * D + c];
        frame[(x_reg + c) * LANES + n] = diff * flip[c];
        r2 = r2 + diff * diff;
    }}
    const R hij = (hi + h[j]) * (R)0.5;
    const R rc = support * hij;
    frame[r_reg * LANES + n] = {sqrt}(r2);
    frame[h_reg * LANES + n] = hij;
    jout[n] = (unsigned)j;
    if (sign)
        for (int c = 0; c < 3; c++) sign[c * LANES + n] = flip[c];
    return n + (r2 < rc * rc && r2 != 0 && ((sources >> group[j]) & 1));
}}

#if defined(__AVX2__)
typedef {v} V;
{table}
#endif

size_t walk(const unsigned *list, size_t count, const R *x, const R *h, const unsigned *group,
            unsigned long long sources, const R *yi, const R *flip, R hi, R support, R *frame, size_t x_reg,
            size_t r_reg, size_t h_reg, unsigned *jout, R *sign, size_t *np) {{
    size_t n = *np, i = 0;
#if defined(__AVX2__)
{ys}    const V vhi = _mm256_set1_{ps}(hi), vsupport = _mm256_set1_{ps}(support);
    const V half = _mm256_set1_{ps}(0.5), zero = _mm256_setzero_{ps}();
    /* W entries at a time while their lanes fit the batch: it fills up only at its last lane. */
    for (; i + W <= count && n + W <= LANES; i += W) {{
{vector}    }}
#endif
    while (i < count && n < LANES) {{
        n = one(list[i], x, h, group, sources, yi, flip, hi, support, frame, x_reg, r_reg, h_reg, jout, sign, n);
        i++;
    }}
    *np = n;
    return i;
}}
"#,
        mask = INDEX_MASK,
        table = pack_table(lanes),
    )
}
