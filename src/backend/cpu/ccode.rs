//! Native code for the neighbour loop's pair program at the full 256-bit vector width: the same
//! scalar SSA graph the JIT compiles ([`super::jit`]), printed as C over GCC/Clang vector
//! extensions (4 f64 or 8 f32 lanes), compiled once by the machine's C compiler for its own
//! processor (`cc -O2 -march=native`, or `$CC`), cached by a hash of the source, the compiler and
//! the processor, and loaded as a shared library.
//!
//! Why C: Cranelift's x86 back end has only 128-bit vectors, so the JIT uses half of AVX2 and a
//! quarter of AVX-512. Every machine that builds pairsum has a C compiler (Rust links with it),
//! and it vectorises for the processor it runs on. The code keeps the JIT's contract: the same
//! function signature, the same operations in the same order (`-ffp-contract=off`: no fused
//! multiply–adds; min/max, exp, ln and pow as `math.rs` computes them; sqrt correctly rounded; the
//! elementary functions, which Cranelift's code lacks, by libm on each lane as the closures call them),
//! and the sums folded with the period every path folds with ([`super::jit::FOLD_BYTES`]), hence
//! bit-identical to the closures and to the JIT — `tests/jit.rs` checks that on every bundled
//! case. An iteration of the loop computes two vectors in f64 (`copies`), their statements
//! interleaved so that one's long dependency chains overlap the other's; each is folded in lane
//! order, so the sums are those of one vector at a time.
//!
//! Where the compiler is missing or fails, the pass keeps the JIT (`PAIRSUM_DEBUG=1` says why).
//! `PAIRSUM_NATIVE=cranelift` turns this path off; `PAIRSUM_CACHE` moves the cache (else
//! `$XDG_CACHE_HOME/pairsum` or `~/.cache/pairsum`, or the temporary directory where that cannot
//! be made). The cache holds only files this module wrote (`pair-HASH.so`, about 16 kB each);
//! deleting it costs one compile per program on the next run.

use super::jit::{fold_lanes, pairwise, JitPair, NativeKind, PairFn, PairSpec, ZERO_ROW};
use super::lower::{Bin, Id, Node, Un};
use super::math::{ExpConsts, LnConsts};
use super::program::{sign_axes, LANES};
use crate::ir::{FieldId, Global, Reduce, Side};
use crate::particles::Real;
use std::collections::HashMap;
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::OnceLock;

/// The compiler and what its code is built for: the cache key's fixed part.
struct Compiler {
    program: String,
    /// The compiler's version line, the flags and the processor: code built for another of any
    /// of these is another file.
    identity: String,
    cache: PathBuf,
}

const FLAGS: [&str; 8] =
    ["-O2", "-march=native", "-ffp-contract=off", "-fno-math-errno", "-fPIC", "-shared", "-std=gnu11", "-w"];

/// The C compiler, when this path is on and one answers `--version`.
fn compiler() -> Option<&'static Compiler> {
    static CC: OnceLock<Option<Compiler>> = OnceLock::new();
    CC.get_or_init(|| {
        let env = crate::config::env();
        if env.no_jit || env.native.as_deref() == Some("cranelift") {
            return None;
        }
        let program = env.cc.clone().unwrap_or_else(|| "cc".into());
        let out = Command::new(&program).arg("--version").output().ok().filter(|o| o.status.success())?;
        let version = String::from_utf8_lossy(&out.stdout).lines().next().unwrap_or("").to_string();
        let identity = format!("{version}\n{}\n{}", FLAGS.join(" "), processor());
        // A cache that cannot be made (a read-only home) moves to the temporary directory.
        let cache = cache_dir(env)
            .into_iter()
            .chain([std::env::temp_dir().join("pairsum-cache")])
            .find(|d| std::fs::create_dir_all(d).is_ok())?;
        Some(Compiler { program, identity, cache })
    })
    .as_ref()
}

thread_local! {
    /// Set by [`without_c`] on this thread.
    static OFF: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Whether pair programs are tried as C first (on this thread).
pub fn enabled() -> bool {
    !OFF.with(|o| o.get()) && compiler().is_some()
}

/// Runs `f` with this path off on this thread: backends built in it compile their pair programs
/// with Cranelift (the tests compare both generators with the closures).
pub fn without_c<R>(f: impl FnOnce() -> R) -> R {
    let was = OFF.with(|o| o.replace(true));
    let r = f();
    OFF.with(|o| o.set(was));
    r
}

/// The processor's model and feature flags (Linux), so that a cache shared between machines
/// never hands one the other's instructions.
fn processor() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let line = |key: &str| info.lines().find(|l| l.starts_with(key)).unwrap_or("").to_string();
    format!("{}\n{}\n{}", std::env::consts::ARCH, line("model name"), line("flags"))
}

/// `PAIRSUM_CACHE`, else `$XDG_CACHE_HOME/pairsum`, else `~/.cache/pairsum`.
fn cache_dir(env: &crate::config::Env) -> Option<PathBuf> {
    let var = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty()).map(PathBuf::from);
    env.cache
        .clone()
        .or_else(|| var("XDG_CACHE_HOME").or_else(|| var("HOME").map(|h| h.join(".cache"))).map(|c| c.join("pairsum")))
}

/// Pair programs and neighbour walks compiled by the C compiler in this process, and the time
/// it all took (ns).
static COMPILED: AtomicUsize = AtomicUsize::new(0);
static WALKS_COMPILED: AtomicUsize = AtomicUsize::new(0);
static COMPILE_NS: AtomicU64 = AtomicU64::new(0);

/// What this process has asked of the C compiler so far.
pub struct BuildStats {
    pub pair_programs: usize,
    /// Neighbour walks (`super::cwalk`), one per precision and dimension.
    pub walks: usize,
    pub secs: f64,
    pub cache: &'static Path,
}

impl BuildStats {
    /// "2 pair programs and the neighbour walk", or `None` when nothing was compiled.
    pub fn describe(&self) -> Option<String> {
        let pairs = match self.pair_programs {
            0 => None,
            1 => Some("1 pair program".to_string()),
            n => Some(format!("{n} pair programs")),
        };
        let walks = match self.walks {
            0 => None,
            1 => Some("the neighbour walk".to_string()),
            n => Some(format!("{n} neighbour walks")),
        };
        match (pairs, walks) {
            (Some(p), Some(w)) => Some(format!("{p} and {w}")),
            (p, w) => p.or(w),
        }
    }
}

pub fn build_stats() -> Option<BuildStats> {
    let c = compiler()?;
    Some(BuildStats {
        pair_programs: COMPILED.load(Ordering::Relaxed),
        walks: WALKS_COMPILED.load(Ordering::Relaxed),
        secs: COMPILE_NS.load(Ordering::Relaxed) as f64 * 1e-9,
        cache: &c.cache,
    })
}

/// Compiles the pair program as C, or says why not.
pub fn compile_pair<T: Real>(spec: &PairSpec) -> Result<JitPair<T>, String> {
    let cc = compiler().ok_or("no C compiler")?;
    super::jit::check(spec)?;
    let (source, gathers) = Printer::<T>::new(spec).print();
    if crate::config::env().debug >= 2 {
        eprintln!("C pair program:\n{source}");
    }
    let lib = build(cc, &source, &COMPILED)?;
    // SAFETY: `pair` was printed with exactly this signature (C calling convention), and the
    // library stays loaded as long as the function pointer (both are kept in the JitPair).
    let func = unsafe {
        let sym: libloading::Symbol<PairFn<T>> = lib.get(b"pair\0").map_err(|e| e.to_string())?;
        *sym
    };
    Ok(JitPair::from_library(func, gathers, lib, NativeKind::C))
}

/// The shared library of a C source of this module's kind (`super::cwalk`'s walk), built as a
/// pair program's is.
pub(super) fn build_source(source: &str) -> Result<libloading::Library, String> {
    build(compiler().ok_or("no C compiler")?, source, &WALKS_COMPILED)
}

/// The shared library of `source`: from the cache, else compiled into it (written beside its
/// final name and renamed, so that processes compiling the same program at once never load a
/// half-written file).
fn build(cc: &Compiler, source: &str, compiled: &AtomicUsize) -> Result<libloading::Library, String> {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    (cc.identity.as_str(), source).hash(&mut h);
    let name = format!("pair-{:016x}", h.finish());
    let lib = cc.cache.join(format!("{name}.so"));
    if lib.is_file() {
        // SAFETY: a library this function wrote; loading runs no initialisers of ours.
        if let Ok(l) = unsafe { libloading::Library::new(&lib) } {
            return Ok(l);
        }
    }
    let tag = format!("{}-{:?}", std::process::id(), std::thread::current().id()).replace(['(', ')'], "");
    let c_file = cc.cache.join(format!("{name}.{tag}.c"));
    let tmp = cc.cache.join(format!("{name}.{tag}.so"));
    std::fs::write(&c_file, source).map_err(|e| format!("{}: {e}", c_file.display()))?;
    let t0 = std::time::Instant::now();
    let out = Command::new(&cc.program).args(FLAGS).arg("-o").arg(&tmp).arg(&c_file).arg("-lm").output();
    let _ = std::fs::remove_file(&c_file);
    let out = out.map_err(|e| format!("{}: {e}", cc.program))?;
    if !out.status.success() {
        let _ = std::fs::remove_file(&tmp);
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(format!("{} failed: {}", cc.program, err.lines().take(5).collect::<Vec<_>>().join("\n")));
    }
    compiled.fetch_add(1, Ordering::Relaxed);
    COMPILE_NS.fetch_add(t0.elapsed().as_nanos() as u64, Ordering::Relaxed);
    std::fs::rename(&tmp, &lib).map_err(|e| format!("{}: {e}", lib.display()))?;
    // SAFETY: as above.
    unsafe { libloading::Library::new(&lib) }.map_err(|e| e.to_string())
}

/// Prints the pair program as one C function, `pair`, with the JIT's signature.
struct Printer<'a, T> {
    spec: &'a PairSpec<'a>,
    /// Statements before the loop (constants, broadcasts) and in its body.
    head: String,
    body: String,
    /// Constants made so far, by the bits of their value rounded to T.
    consts: HashMap<u64, String>,
    temps: usize,
    _t: std::marker::PhantomData<T>,
}

/// The C types and helpers of one precision: V the vector of reals, I of signed and U of
/// unsigned integers of the same width, W lanes.
fn prelude<T: Real>() -> String {
    let w = fold_lanes::<T>();
    let (r, i, u, sqrt) = if T::BYTES == 8 {
        ("double", "long long", "unsigned long long", "_mm256_sqrt_pd")
    } else {
        ("float", "int", "unsigned int", "_mm256_sqrt_ps")
    };
    format!(
        r#"/* generated by pairsum: a pair program (backend/cpu/ccode.rs) */
#include <math.h>
#include <stddef.h>
#include <string.h>
#if defined(__AVX__)
#include <immintrin.h>
#endif
typedef {r} R;
typedef {i} SI;
typedef {u} UI;
typedef R V __attribute__((vector_size(32)));
typedef SI I __attribute__((vector_size(32)));
typedef UI U __attribute__((vector_size(32)));
enum {{ W = {w}, LANES = {LANES} }};
static inline V ld(const R *p) {{ V v; memcpy(&v, p, sizeof v); return v; }}
static inline void st(R *p, V v) {{ memcpy(p, &v, sizeof v); }}
static inline V sel(I m, V a, V b) {{ return (V)((m & (I)a) | (~m & (I)b)); }}
static inline V truth(I m, V one) {{ return (V)(m & (I)one); }}
static inline R bits(UI b) {{ R x; memcpy(&x, &b, sizeof x); return x; }}
static inline V vsqrt(V a) {{
#if defined(__AVX__)
    return (V){sqrt}(a);
#else
    V r;
    for (int k = 0; k < W; k++) r[k] = __builtin_sqrt{suffix}(a[k]);
    return r;
#endif
}}
static const R zero_row[{zeros}];
/* an elementary function (libm's, as the closures call it) on each lane */
#define LANEWISE(f, a) ({{ V r_; for (int k_ = 0; k_ < W; k_++) r_[k_] = f((a)[k_]); r_; }})
"#,
        suffix = if T::BYTES == 8 { "" } else { "f" },
        zeros = ZERO_ROW.len(),
    )
}

impl<'a, T: Real> Printer<'a, T> {
    fn new(spec: &'a PairSpec<'a>) -> Self {
        Printer {
            spec,
            head: String::new(),
            body: String::new(),
            consts: HashMap::new(),
            temps: 0,
            _t: std::marker::PhantomData,
        }
    }

    fn w(&self) -> usize {
        fold_lanes::<T>()
    }

    /// A constant vector of `v` rounded to T, defined once before the loop.
    fn splat(&mut self, v: f64) -> String {
        let bits = T::from_f64(v).to_f64().to_bits();
        if let Some(n) = self.consts.get(&bits) {
            return n.clone();
        }
        let name = format!("k{}", self.consts.len());
        let scalar = self.real_bits(v);
        let lanes = vec![scalar; self.w()].join(", ");
        let _ = writeln!(self.head, "    const V {name} = {{{lanes}}};");
        self.consts.insert(bits, name.clone());
        name
    }

    /// The exact value of `v` rounded to T, as a C expression of its bits.
    fn real_bits(&self, v: f64) -> String {
        if T::BYTES == 8 {
            format!("bits(0x{:016x}ull)", v.to_bits())
        } else {
            format!("bits(0x{:08x}u)", (v as f32).to_bits())
        }
    }

    /// A vector of the integer `v` (wrapped to the lane width).
    fn splat_int(&self, v: i64) -> String {
        let lane = if T::BYTES == 8 { format!("{v}ll") } else { format!("{}", v as i32) };
        format!("((I){{{}}})", vec![lane; self.w()].join(", "))
    }

    /// The integer bits of `v` rounded to T.
    fn int_bits(&self, v: f64) -> i64 {
        if T::BYTES == 8 {
            v.to_bits() as i64
        } else {
            (v as f32).to_bits() as i32 as i64
        }
    }

    /// A new temporary holding `expr`, in the loop body.
    fn let_(&mut self, ty: &str, expr: String) -> String {
        self.temps += 1;
        let name = format!("t{}", self.temps);
        let _ = writeln!(self.body, "        {ty} {name} = {expr};");
        name
    }

    fn print(mut self) -> (String, Vec<FieldId>) {
        let spec = self.spec;
        let w = self.w();
        let gathers = super::jit::gathered_fields(spec);
        let one = self.splat(1.0);
        let zero = self.splat(0.0);
        let mut vals: HashMap<Id, String> = HashMap::new();
        let _ = writeln!(self.head, "    const V vtime = {{{}}};", vec!["time"; w].join(", "));
        let _ = writeln!(self.head, "    const V vdt = {{{}}};", vec!["dt"; w].join(", "));
        for (id, u) in spec.broadcast {
            let x = format!("dest[{}]", u * LANES);
            let _ = writeln!(self.head, "    const V b{id} = {{{}}};", vec![x.as_str(); w].join(", "));
            vals.insert(*id, format!("b{id}"));
        }
        for id in spec.nodes {
            if let Node::Const(bits) = spec.graph.nodes[*id as usize] {
                let v = self.splat(f64::from_bits(bits));
                vals.insert(*id, v);
            }
        }
        let accs: Vec<String> = spec
            .folded
            .iter()
            .enumerate()
            .map(|(k, (_, _, r))| {
                let id = self.splat(r.identity());
                let _ = writeln!(self.head, "    V acc{k} = {id};");
                format!("acc{k}")
            })
            .collect();
        // The loop body: lane k of a vector is lane base + k of the frame.
        let _ = writeln!(self.body, "        R *lane = frame + base;");
        for k in 0..w {
            let _ = writeln!(self.body, "        const size_t j{k} = jp[base + {k}];");
        }
        if spec.signs {
            let _ = writeln!(self.body, "        const R *sg = sign + base;");
        }
        let preset: HashMap<Id, usize> = spec.preset.iter().copied().collect();
        let mut rows: HashMap<FieldId, Vec<String>> = HashMap::new();
        for id in &super::jit::demand_order(spec) {
            if vals.contains_key(id) {
                continue;
            }
            if let Some(r) = preset.get(id) {
                let v = self.let_("const V", format!("ld(lane + {})", r * LANES));
                vals.insert(*id, v);
                continue;
            }
            let node = spec.graph.nodes[*id as usize];
            let v = match node {
                Node::Const(_) | Node::PairX(_) | Node::PairR | Node::PairH => {
                    unreachable!("constants and pair values are preset")
                }
                Node::Global(g) => match g {
                    Global::Time => "vtime".to_string(),
                    Global::Dt => "vdt".to_string(),
                    Global::Dim => self.splat(spec.dim as f64),
                },
                Node::Load { field, comp, side: Side::J } => {
                    let comps = crate::ir::components(spec.model.field(field).ty.shape, spec.dim);
                    let slot = gathers.iter().position(|f| *f == field).expect("gathered field");
                    // Each lane's row of the field, once per field; a neighbour whose group does
                    // not store it reads the zero row.
                    let stored_on = spec.partial.iter().find(|(f, _)| *f == field).map(|(_, set)| *set);
                    let row_of = |p: &mut Self, k: usize| {
                        let row = format!("cols[{slot}] + j{k} * {comps}");
                        let row = match stored_on {
                            Some(set) => format!("((0x{:x}ull >> group[j{k}]) & 1 ? {row} : zero_row)", set.0),
                            None => row,
                        };
                        p.let_("const R *", row)
                    };
                    let row = rows.entry(field).or_insert_with(|| (0..w).map(|k| row_of(&mut self, k)).collect());
                    let lanes: Vec<String> = row.iter().map(|r| format!("{r}[{comp}]")).collect();
                    let mut v = format!("(V){{{}}}", lanes.join(", "));
                    if spec.signs {
                        for a in sign_axes(spec.model.field(field).ty.shape, spec.dim, comp as usize) {
                            v = format!("({v}) * ld(sg + {})", a * LANES);
                        }
                    }
                    self.let_("const V", v)
                }
                Node::Un(op, a) => {
                    let a = vals[&a].clone();
                    match op {
                        Un::Neg => self.let_("const V", format!("-{a}")),
                        Un::Abs => {
                            let mask = self.splat_int(if T::BYTES == 8 { i64::MAX } else { i32::MAX as i64 });
                            self.let_("const V", format!("(V)({mask} & (I){a})"))
                        }
                        Un::Sqrt => self.let_("const V", format!("vsqrt({a})")),
                        Un::Not => self.let_("const V", format!("truth({a} == {zero}, {one})")),
                        Un::Exp => self.exp(&a, T::EXP),
                        Un::Ln => self.ln(&a, T::LN),
                        Un::Elementary(e) => {
                            let f = if T::BYTES == 8 { e.name().to_string() } else { format!("{}f", e.name()) };
                            self.let_("const V", format!("LANEWISE({f}, {a})"))
                        }
                    }
                }
                Node::Bin(op, a, c) => {
                    let (a, c) = (vals[&a].clone(), vals[&c].clone());
                    self.bin(op, &a, &c, &one, &zero)
                }
                Node::Select(c, a, e) => {
                    let (c, a, e) = (&vals[&c], &vals[&a], &vals[&e]);
                    self.let_("const V", format!("sel({c} != {zero}, {a}, {e})"))
                }
                Node::Param { param, comp, side: Side::J } => {
                    let off = spec.param_offset[param.index()] + comp as usize;
                    let stride = spec.param_stride;
                    let lanes: Vec<String> =
                        (0..w).map(|k| format!("params[(size_t)material[j{k}] * {stride} + {off}]")).collect();
                    self.let_("const V", format!("(V){{{}}}", lanes.join(", ")))
                }
                Node::InGroup(Side::J, set) => {
                    let lanes: Vec<String> =
                        (0..w).map(|k| format!("(R)((0x{set:x}ull >> group[j{k}]) & 1)")).collect();
                    self.let_("const V", format!("(V){{{}}}", lanes.join(", ")))
                }
                Node::Load { .. } | Node::Param { .. } | Node::InGroup(..) => unreachable!("checked by `jit::check`"),
            };
            vals.insert(*id, v);
        }
        let value = |p: &mut Self, vals: &HashMap<Id, String>, id: &Id| match (vals.get(id), preset.get(id)) {
            (Some(v), _) => v.clone(),
            (None, Some(r)) => p.let_("const V", format!("ld(lane + {})", r * LANES)),
            (None, None) => unreachable!("every output is computed or preset"),
        };
        let iota: Vec<String> = (0..w).map(|k| format!("(SI)(base + {k})")).collect();
        let live =
            self.let_("const I", format!("(I){{{}}} < (I){{{}}}", iota.join(", "), vec!["(SI)end"; w].join(", ")));
        // Lanes from `end` on keep what they hold: past a full batch they are the next register's
        // first lanes, another particle's outputs.
        for (id, r) in spec.outputs {
            let v = value(&mut self, &vals, id);
            let _ = writeln!(self.body, "        st(lane + {0}, sel({live}, {v}, ld(lane + {0})));", r * LANES);
        }
        // Lanes at or past `end` contribute the identity (as `fold_partials` pads).
        for ((id, _, r), acc) in spec.folded.iter().zip(&accs) {
            let v = value(&mut self, &vals, id);
            let identity = self.splat(r.identity());
            let masked = self.let_("const V", format!("sel({live}, {v}, {identity})"));
            let _ = writeln!(self.body, "        {acc} = {};", combine(*r, acc, &masked));
        }
        let mut tail = String::new();
        for ((_, slot, r), acc) in spec.folded.iter().zip(&accs) {
            let lanes: Vec<String> = (0..w).map(|k| format!("{acc}[{k}]")).collect();
            let h = pairwise(&lanes, &mut |a, b| scalar_combine(*r, &a, &b));
            let _ = writeln!(tail, "    slots[{slot}] = {};", scalar_combine(*r, &format!("slots[{slot}]"), &h));
        }
        let real = if T::BYTES == 8 { "double" } else { "float" };
        let source = format!(
            "{prelude}
void pair(R *frame, const unsigned *jp, const R *const *cols, size_t start, size_t end, const R *sign,
          const unsigned *group, const unsigned *material, const R *params, const R *dest, R *slots,
          {real} time, {real} dt) {{
{head}    for (size_t base = start; base < end; base += {step} * W) {{
{body}    }}
{tail}}}
",
            prelude = prelude::<T>(),
            head = self.head,
            step = copies::<T>(),
            body = interleaved(&self.body, copies::<T>(), w),
        );
        (source, gathers)
    }

    fn bin(&mut self, op: Bin, a: &str, c: &str, one: &str, zero: &str) -> String {
        let e = match op {
            Bin::Add => format!("{a} + {c}"),
            Bin::Sub => format!("{a} - {c}"),
            Bin::Mul => format!("{a} * {c}"),
            Bin::Div => format!("{a} / {c}"),
            Bin::Lt => format!("truth({a} < {c}, {one})"),
            Bin::Le => format!("truth({a} <= {c}, {one})"),
            Bin::Gt => format!("truth({a} > {c}, {one})"),
            Bin::Ge => format!("truth({a} >= {c}, {one})"),
            Bin::Eq => format!("truth({a} == {c}, {one})"),
            Bin::Ne => format!("truth({a} != {c}, {one})"),
            Bin::And => format!("truth(({a} != {zero}) & ({c} != {zero}), {one})"),
            Bin::Or => format!("truth(({a} != {zero}) | ({c} != {zero}), {one})"),
            // program::lane_min / lane_max: c when a is NaN or c is beyond a, else a.
            Bin::Min => format!("sel(({a} != {a}) | ({c} < {a}), {c}, {a})"),
            Bin::Max => format!("sel(({a} != {a}) | ({c} > {a}), {c}, {a})"),
            Bin::Pow => return self.pow(a, c, one, zero),
        };
        self.let_("const V", e)
    }

    /// `math::pow_f64` / `pow_f32`: exp(y · ln x), 1 where y = 0 or x = 1.
    fn pow(&mut self, x: &str, y: &str, one: &str, zero: &str) -> String {
        let l = self.ln(x, T::LN);
        let a = self.let_("const V", format!("{y} * {l}"));
        let p = self.exp(&a, T::EXP);
        self.let_("const V", format!("sel(({y} == {zero}) | ({x} == {one}), {one}, {p})"))
    }

    /// `math::exp_f64` / `exp_f32`, operation for operation (as the JIT's `exp`).
    fn exp(&mut self, x: &str, k: &ExpConsts) -> String {
        let (lo, hi) = (self.splat(k.lo), self.splat(k.hi));
        let x1 = self.let_("const V", format!("sel({x} > {hi}, {hi}, {x})"));
        let x = self.let_("const V", format!("sel({x} < {lo}, {lo}, {x1})"));
        let (magic, log2e) = (self.splat(k.magic), self.splat(k.log2e));
        let t = self.let_("const V", format!("{x} * {log2e}"));
        let t = self.let_("const V", format!("{t} + {magic}"));
        let nf = self.let_("const V", format!("{t} - {magic}"));
        let (ln2_hi, ln2_lo) = (self.splat(k.ln2_hi), self.splat(k.ln2_lo));
        let r = self.let_("const V", format!("{x} - {nf} * {ln2_hi}"));
        let r = self.let_("const V", format!("{r} - {nf} * {ln2_lo}"));
        let p = self.horner(k.coeffs, &r);
        let magic_int = self.splat_int(self.int_bits(k.magic));
        let n = self.let_("const I", format!("(I){t} - {magic_int}"));
        let zero = self.splat(0.0);
        let (up, down) = (self.splat_int(k.margin), self.splat_int(-k.margin));
        let neg = self.let_("const I", format!("{x} < {zero}"));
        let m = self.let_("const I", format!("({neg} & {up}) | (~{neg} & {down})"));
        let bias = self.splat_int(k.bias);
        let e1 = self.let_("const I", format!("(I)((U)({n} + {m} + {bias}) << {})", k.mantissa));
        let e2 = self.let_("const I", format!("(I)((U)({bias} - {m}) << {})", k.mantissa));
        let y = self.let_("const V", format!("{p} * (V){e1}"));
        self.let_("const V", format!("{y} * (V){e2}"))
    }

    /// c[0] + x (c[1] + x (…)), from the last coefficient in: a multiplication, then an addition.
    fn horner(&mut self, c: &[f64], x: &str) -> String {
        let mut p = self.splat(c[c.len() - 1]);
        for ci in c[..c.len() - 1].iter().rev() {
            let ci = self.splat(*ci);
            let m = self.let_("const V", format!("{p} * {x}"));
            p = self.let_("const V", format!("{m} + {ci}"));
        }
        p
    }

    /// `math::ln_f64` / `ln_f32`, operation for operation (as the JIT's `ln`).
    fn ln(&mut self, x: &str, k: &LnConsts) -> String {
        let min_normal = self.splat(k.min_normal);
        let up = self.splat(2f64.powi(k.scale as i32));
        let tiny = self.let_("const I", format!("{x} < {min_normal}"));
        let xs = self.let_("const V", format!("sel({tiny}, {x} * {up}, {x})"));
        let e = self.let_("const I", format!("(I)((U){xs} >> {})", k.mantissa));
        let mant_mask = self.splat_int((1i64 << k.mantissa) - 1);
        let mant = self.let_("const I", format!("(I){xs} & {mant_mask}"));
        let sqrt2 = self.splat_int(k.sqrt2_mantissa);
        let one_int = self.splat_int(1);
        let big = self.let_("const I", format!("({mant} > {sqrt2}) & {one_int}"));
        let bias = self.splat_int(k.bias);
        let zbits = self.let_("const I", format!("{mant} | (I)((U)({bias} - {big}) << {})", k.mantissa));
        let scale = self.splat_int(k.scale);
        let n = self.let_("const I", format!("{e} - {bias} + {big} - ({tiny} & {scale})"));
        let (one, two, half) = (self.splat(1.0), self.splat(2.0), self.splat(0.5));
        let f = self.let_("const V", format!("(V){zbits} - {one}"));
        let d = self.let_("const V", format!("{two} + {f}"));
        let s = self.let_("const V", format!("{f} / {d}"));
        let wv = self.let_("const V", format!("{s} * {s}"));
        let r = self.horner(k.lg, &wv);
        let r = self.let_("const V", format!("{r} * {wv}"));
        let hf = self.let_("const V", format!("{half} * {f}"));
        let hfsq = self.let_("const V", format!("{hf} * {f}"));
        let magic = T::EXP.magic;
        let magic_int = self.splat_int(self.int_bits(magic));
        let magic = self.splat(magic);
        let nf = self.let_("const V", format!("(V)({n} + {magic_int}) - {magic}"));
        let (ln2_hi, ln2_lo) = (self.splat(k.ln2_hi), self.splat(k.ln2_lo));
        // nf·ln2_hi − ((hfsq − (s·(hfsq + r) + nf·ln2_lo)) − f)
        let a = self.let_("const V", format!("{s} * ({hfsq} + {r})"));
        let a = self.let_("const V", format!("{a} + {nf} * {ln2_lo}"));
        let a = self.let_("const V", format!("{hfsq} - {a}"));
        let a = self.let_("const V", format!("{a} - {f}"));
        let y = self.let_("const V", format!("{nf} * {ln2_hi} - {a}"));
        let zero = self.splat(0.0);
        let (minus_inf, inf, nan) = (self.splat(f64::NEG_INFINITY), self.splat(f64::INFINITY), self.splat(f64::NAN));
        let y = self.let_("const V", format!("sel({x} == {zero}, {minus_inf}, {y})"));
        let y = self.let_("const V", format!("sel({x} == {inf}, {inf}, {y})"));
        self.let_("const V", format!("sel(({x} < {zero}) | ({x} != {x}), {nan}, {y})"))
    }
}

/// How many vectors of consecutive lanes an iteration of the loop computes: `LOOP_LANES` (or
/// `PAIRSUM_C_LANES`) lanes, their statements interleaved, so the processor overlaps the long
/// dependency chains (a polynomial's, a division's) of one vector with the other's.
fn copies<T: Real>() -> usize {
    let lanes = crate::config::env().c_lanes.unwrap_or(LOOP_LANES);
    (lanes / fold_lanes::<T>()).clamp(1, 4)
}

/// Lanes per iteration: two vectors of f64 (PySPH's `impact3d` ran 1.11× faster than with one,
/// the dam break 1.05×), one of f32 (two were no faster), on a 2-core AMD EPYC with AVX2.
const LOOP_LANES: usize = 8;

/// The loop body for `copies` vectors of `w` lanes each, statement by statement: copy h's
/// temporaries, neighbours and lane pointers are suffixed `_h` and start `h · w` lanes on. The
/// folds come in lane order, copy 0's first, so the sums are those of one vector at a time. A
/// name the printer gives to something per lane must be one [`copy_of`] renames (t…, j…, `lane`,
/// `sg`, `base`).
fn interleaved(body: &str, copies: usize, w: usize) -> String {
    let mut out = String::with_capacity(body.len() * copies);
    for line in body.lines() {
        for h in 0..copies {
            out.push_str(&copy_of(line, h, w));
            out.push('\n');
        }
    }
    out
}

/// `line` of the body as copy `h` states it.
fn copy_of(line: &str, h: usize, w: usize) -> String {
    let mut out = String::with_capacity(line.len() + 16);
    let mut rest = line;
    while let Some(start) = rest.find(|c: char| c.is_ascii_alphabetic() || c == '_') {
        out.push_str(&rest[..start]);
        let after = &rest[start..];
        let len = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(after.len());
        let word = &after[..len];
        let numbered = |p: char| word.len() > 1 && word.starts_with(p) && word[1..].bytes().all(|b| b.is_ascii_digit());
        // A number's letters (1e-3, 0x1ull) are not names: the scan starts only at a name.
        let in_number = out.chars().last().is_some_and(|c| c.is_ascii_digit());
        if !in_number && (numbered('t') || numbered('j') || word == "lane" || word == "sg") {
            let _ = write!(out, "{word}_{h}");
        } else if !in_number && word == "base" && h > 0 {
            let _ = write!(out, "(base + {})", h * w);
        } else {
            out.push_str(word);
        }
        rest = &after[len..];
    }
    out.push_str(rest);
    out
}

/// `op(a, b)` of a reduction on vectors, as `fold_partials` computes it.
fn combine(r: Reduce, a: &str, b: &str) -> String {
    match r {
        Reduce::Sum => format!("{a} + {b}"),
        Reduce::Min => format!("sel(({a} != {a}) | ({b} < {a}), {b}, {a})"),
        Reduce::Max => format!("sel(({a} != {a}) | ({b} > {a}), {b}, {a})"),
    }
}

/// `op(a, b)` of a reduction on scalars.
fn scalar_combine(r: Reduce, a: &str, b: &str) -> String {
    match r {
        Reduce::Sum => format!("({a} + {b})"),
        Reduce::Min => format!("(({a}) != ({a}) || ({b}) < ({a}) ? ({b}) : ({a}))"),
        Reduce::Max => format!("(({a}) != ({a}) || ({b}) > ({a}) ? ({b}) : ({a}))"),
    }
}

#[cfg(test)]
mod tests {
    use super::copy_of;

    #[test]
    fn a_second_copy_renames_temporaries_neighbours_and_lanes_and_moves_base_but_not_constants_or_numbers() {
        let line = "        const V t12 = sel(t3 < k7, ld(lane + 64) * ld(sg + 0), (V){t9[0], t10[1]}) + (R)((0x1ull >> group[j3]) & 1) + 1e-3 + jp[base + 2] + (I){4843621399236968448ll};";
        assert_eq!(
            copy_of(line, 1, 4),
            "        const V t12_1 = sel(t3_1 < k7, ld(lane_1 + 64) * ld(sg_1 + 0), (V){t9_1[0], t10_1[1]}) + (R)((0x1ull >> group[j3_1]) & 1) + 1e-3 + jp[(base + 4) + 2] + (I){4843621399236968448ll};"
        );
        assert_eq!(copy_of("        acc0 = acc0 + t170;", 0, 4), "        acc0 = acc0 + t170_0;");
    }
}
