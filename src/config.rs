//! The environment variables pairsum reads, read once (the first time any is asked for) and
//! documented in one place (`docs/ARCHITECTURE.md`, "Configuration").

use std::path::PathBuf;
use std::sync::OnceLock;

/// Everything pairsum takes from its environment.
#[derive(Clone, Debug, Default)]
pub struct Env {
    /// `PAIRSUM_ADAPTER`: the GPU adapter to use (a part of its name); also lets `--backend auto`
    /// take a software adapter.
    pub adapter: Option<String>,
    /// `PAIRSUM_CASES`: the directory of the bundled cases.
    pub cases: Option<PathBuf>,
    /// `PAIRSUM_STDLIB`: the stdlib directory (else the source tree's, else the embedded copy).
    pub stdlib: Option<PathBuf>,
    /// `PAIRSUM_DEBUG`: 1 prints the CPU backend's programs, 2 also their SSA.
    pub debug: u8,
    /// `PAIRSUM_NO_WIDE_SIMD`: the CPU backend keeps to its portable lane loops.
    pub no_wide_simd: bool,
    /// `PAIRSUM_NO_JIT`: the CPU backend runs its neighbour loops as closures, not native code.
    pub no_jit: bool,
    /// `PAIRSUM_NATIVE`: `cranelift` keeps the CPU backend's pair programs on Cranelift instead of
    /// the machine's C compiler, and its neighbour walk in Rust.
    pub native: Option<String>,
    /// `PAIRSUM_C_LANES`: lanes per iteration of the C pair programs' loop (else 8).
    pub c_lanes: Option<usize>,
    /// `CC`: the C compiler for the pair programs (else `cc`).
    pub cc: Option<String>,
    /// `PAIRSUM_CACHE`: where compiled pair programs are kept.
    pub cache: Option<PathBuf>,
    /// `PAIRSUM_GPU_MEMORY_LIMIT`: bytes the GPU backend may use (tests its out-of-memory path).
    pub gpu_memory_limit: Option<u64>,
    /// `PAIRSUM_WGSL_FAULT`: breaks the first generated kernel (tests the path of a rejected module).
    pub wgsl_fault: bool,
    /// `PAIRSUM_GPU_CELLS_PER_CUTOFF`: the GPU cell list's cells per cut-off (1, 2, 4 or 8) instead
    /// of the scene's choice (`backend::gpu::runtime::cells_per_cutoff`); as written, checked there.
    pub gpu_cells_per_cutoff: Option<String>,
    /// `PAIRSUM_HALO_SKIN`: a run split into domains keeps its halos' skin at this fraction of the
    /// largest cut-off instead of fitting it to the fastest particle (`backend::domains`).
    pub halo_skin: Option<f64>,
}

fn var(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.is_empty())
}

impl Env {
    fn read() -> Env {
        Env {
            adapter: var("PAIRSUM_ADAPTER"),
            cases: var("PAIRSUM_CASES").map(PathBuf::from),
            stdlib: var("PAIRSUM_STDLIB").map(PathBuf::from),
            debug: var("PAIRSUM_DEBUG").map(|v| if v == "2" { 2 } else { 1 }).unwrap_or(0),
            no_wide_simd: var("PAIRSUM_NO_WIDE_SIMD").is_some(),
            no_jit: var("PAIRSUM_NO_JIT").is_some(),
            native: var("PAIRSUM_NATIVE"),
            c_lanes: var("PAIRSUM_C_LANES").and_then(|v| v.parse().ok()),
            cc: var("CC"),
            cache: var("PAIRSUM_CACHE").map(PathBuf::from),
            gpu_memory_limit: var("PAIRSUM_GPU_MEMORY_LIMIT").and_then(|v| v.parse().ok()),
            wgsl_fault: var("PAIRSUM_WGSL_FAULT").is_some(),
            gpu_cells_per_cutoff: var("PAIRSUM_GPU_CELLS_PER_CUTOFF"),
            halo_skin: var("PAIRSUM_HALO_SKIN").and_then(|v| v.parse().ok()).filter(|f: &f64| *f > 0.0),
        }
    }
}

/// The environment, read on first use.
pub fn env() -> &'static Env {
    static ENV: OnceLock<Env> = OnceLock::new();
    ENV.get_or_init(Env::read)
}
