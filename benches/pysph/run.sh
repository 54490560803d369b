#!/usr/bin/env bash
# PySPH 1.0b2 against pairsum on PySPH's own 3D solid example, side by side on this machine in one
# run (issue 11). Not part of the test command: it installs PySPH into a virtual environment
# (target/pysph-venv, or $PAIRSUM_PYSPH_VENV) the first time, which takes a few minutes.
#
#   benches/pysph/run.sh            # 50 steps, all cores
#   STEPS=20 THREADS=1 benches/pysph/run.sh
#
# Times exclude set-up on both sides: PySPH's "Run took" (after its code generation and a warm-up
# run that compiles it), pairsum's stepping time (after the case is built and compiled).
# Prints per particle-step times and the ratios: PySPH / pairsum (f64), f64 / f32, and the
# pair programs compiled as C (256-bit vectors) against Cranelift's (128-bit) and the closures; then
# `pairsum bench`'s generated/hand-written.
set -euo pipefail
cd "$(dirname "$0")/../.."
STEPS=${STEPS:-50}
THREADS=${THREADS:-$(nproc)}

. benches/pysph/venv.sh
cargo build --release -q
PAIRSUM=target/release/pairsum
EXAMPLE=$("$VENV/bin/python" -c 'import os, pysph; print(os.path.join(os.path.dirname(pysph.__file__), "examples", "solid_mech", "impact3d.py"))')
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

pysph() {
    OMP_NUM_THREADS=$THREADS "$VENV/bin/python" "$EXAMPLE" --openmp --disable-output -d "$WORK/pysph" "$@"
}
echo "PySPH: warm-up run (compiles the generated code)" >&2
pysph --max-steps 1 >/dev/null 2>&1
echo "PySPH: $STEPS steps" >&2
pysph --max-steps "$STEPS" >"$WORK/pysph.log" 2>&1
pysph_n=$(sed -n 's/^ *Total: \([0-9]*\)$/\1/p' "$WORK/pysph.log" | tail -1)
pysph_s=$(sed -n 's/^Run took: \([0-9.]*\) secs$/\1/p' "$WORK/pysph.log" | tail -1)

# pairsum: "<case>: N particles, S steps in T s on cpu (...)"
pairsum() {
    local label=$1
    shift
    echo "pairsum: $STEPS steps, $label" >&2
    RAYON_NUM_THREADS=$THREADS "$@" "$PAIRSUM" run pysph_impact3d --backend cpu --max-steps "$STEPS" --quiet --force \
        --out "$WORK/pairsum" "${EXTRA[@]}" >"$WORK/run.log" 2>&1 || { cat "$WORK/run.log" >&2; exit 1; }
    sed -n 's/^pysph_impact3d: \([0-9]*\) particles, [0-9]* steps in \([0-9.]*\) s.*/\1 \2/p' "$WORK/run.log"
}
EXTRA=(--precision f64)
read -r n64 t64 < <(pairsum "f64, C pair programs" env)
read -r _ t64c < <(pairsum "f64, closures" env PAIRSUM_NO_JIT=1)
read -r _ t64k < <(pairsum "f64, Cranelift pair programs" env PAIRSUM_NATIVE=cranelift)
EXTRA=(--precision f32)
read -r _ t32 < <(pairsum "f32, C pair programs" env)

per() { awk -v t="$1" -v n="$2" -v s="$STEPS" 'BEGIN { printf "%.2f", 1e6 * t / (n * s) }'; }
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a / b }'; }
p_pysph=$(per "$pysph_s" "$pysph_n")
p64=$(per "$t64" "$n64")
p64c=$(per "$t64c" "$n64")
p64k=$(per "$t64k" "$n64")
p32=$(per "$t32" "$n64")
echo
echo "PySPH impact3d, $STEPS steps, $THREADS threads, $(uname -m), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
printf '%-36s %10s %10s %14s\n' "" particles "time [s]" "µs/particle-step"
printf '%-36s %10s %10s %14s\n' "PySPH 1.0b2 (OpenMP)" "$pysph_n" "$pysph_s" "$p_pysph"
printf '%-36s %10s %10s %14s\n' "pairsum CPU f64 (C pair code)" "$n64" "$t64" "$p64"
printf '%-36s %10s %10s %14s\n' "pairsum CPU f64 (Cranelift pair code)" "$n64" "$t64k" "$p64k"
printf '%-36s %10s %10s %14s\n' "pairsum CPU f64 (closures)" "$n64" "$t64c" "$p64c"
printf '%-36s %10s %10s %14s\n' "pairsum CPU f32 (C pair code)" "$n64" "$t32" "$p32"
echo
echo "PySPH / pairsum f64:            $(ratio "$p_pysph" "$p64")×"
echo "PySPH / pairsum f32:            $(ratio "$p_pysph" "$p32")×"
echo "pairsum f64 / f32:              $(ratio "$p64" "$p32")×"
echo "closures / C pair code:         $(ratio "$p64c" "$p64")×"
echo "Cranelift / C pair code:        $(ratio "$p64k" "$p64")×"
echo
RAYON_NUM_THREADS=$THREADS "$PAIRSUM" bench --particles 37000 --reps 3
