#!/usr/bin/env bash
# PySPH 1.0b2's own 2D dam break (examples/dam_break_2d.py, its default WCSPH scheme) against
# pairsum's WCSPH dam break with dynamic boundary particles (cases/dam_break_2d.toml,
# boundary = "dbc"), side by side on this machine in one run. Not part of the test command: it
# installs PySPH into a virtual environment (target/pysph-venv, or $PAIRSUM_PYSPH_VENV) the first
# time (benches/pysph/venv.sh), which takes a few minutes.
#
#   benches/pysph/dam_break.sh              # 500 steps, fastest of 3 rounds, all cores (2 min on 2 cores)
#   STEPS=50 REPS=1 THREADS=1 benches/pysph/dam_break.sh
#   SPACING="1.905 mm" benches/pysph/dam_break.sh
#
# Both run the same number of steps on the same number of threads (OMP_NUM_THREADS for PySPH's
# OpenMP build, RAYON_NUM_THREADS for pairsum); each configuration runs REPS times, interleaved with
# the others, and keeps its fastest time. Times exclude set-up on both sides: PySPH's
# "Run took" (after its code generation, compiled by a warm-up run first), pairsum's stepping time
# (report.json's wall_s, after the case is built and compiled).
# PySPH runs its example as shipped: dx = 0.03 m, 2278 fluid + 1660 boundary particles. pairsum
# runs at SPACING, by default a/30 = 1.905 mm, whose 1800 fluid + 2145 wall particles are the total
# closest to PySPH's (the case's walls are 3a/20 thick: 3 layers at a/20, 5 at a/30).
# The compared figure is the time per particle-step over all particles, fluid and wall; the
# integrators differ in how many force evaluations make a step (PySPH's PEC: one, pairsum's
# symplectic: two), so the script also prints the time per particle-evaluation, a pairsum run
# at PySPH's h = 1.3 Δx (the case's is 1.5 Δx: 1.33× the neighbours) as a third comparison, and
# pairsum with `integrator = symplectic_pec`, which evaluates once per step as PySPH's PEC does.
set -euo pipefail
cd "$(dirname "$0")/../.."
STEPS=${STEPS:-500}
REPS=${REPS:-3}
THREADS=${THREADS:-$(nproc)}
SPACING=${SPACING:-1.905 mm}

. benches/pysph/venv.sh
cargo build --release -q
PAIRSUM=target/release/pairsum
EXAMPLE=$("$VENV/bin/python" -c 'import os, pysph; print(os.path.join(os.path.dirname(pysph.__file__), "examples", "dam_break_2d.py"))')
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

pysph() {
    OMP_NUM_THREADS=$THREADS "$VENV/bin/python" "$EXAMPLE" --openmp --disable-output -d "$WORK/pysph" "$@"
}
# PySPH: prints "particles fluid seconds" from its log ("Total:", "fluid:", "Run took:").
pysph_timed() {
    echo "PySPH: $STEPS steps (round $1 of $REPS)" >&2
    pysph --max-steps "$STEPS" >"$WORK/pysph.log" 2>&1 || { cat "$WORK/pysph.log" >&2; exit 1; }
    local n nf s
    n=$(sed -n 's/^ *Total: \([0-9]*\)$/\1/p' "$WORK/pysph.log" | tail -1)
    nf=$(sed -n 's/^ *fluid: \([0-9]*\)$/\1/p' "$WORK/pysph.log" | tail -1)
    s=$(sed -n 's/^Run took: \([0-9.]*\) secs$/\1/p' "$WORK/pysph.log" | tail -1)
    [ -n "$n" ] && [ -n "$nf" ] && [ -n "$s" ] || { cat "$WORK/pysph.log" >&2; exit 1; }
    echo "$n $nf $s"
}

# pairsum: prints "particles fluid seconds": particles and stepping time from report.json, the
# fluid count from the first VTK file's `body` field (the water column is body 0).
pairsum() {
    local label=$1 case=$2
    shift 2
    echo "pairsum: $STEPS steps, $label" >&2
    rm -rf "$WORK/pairsum"
    RAYON_NUM_THREADS=$THREADS "$PAIRSUM" run "$case" --backend cpu --resolution "$SPACING" --max-steps "$STEPS" \
        --quiet --force --out "$WORK/pairsum" "$@" >"$WORK/run.log" 2>&1 || { cat "$WORK/run.log" >&2; exit 1; }
    python3 - "$WORK/pairsum" <<'EOF'
import base64, glob, json, re, struct, sys
out = sys.argv[1]
r = json.load(open(out + "/report.json"))
vtu = open(sorted(glob.glob(out + "/vtk/*.vtu"))[0]).read()
m = re.search(r'type="(Float64|Float32)" Name="body"[^>]*>\s*([A-Za-z0-9+/=]+)\s*<', vtu)
raw = base64.b64decode(m.group(2))
size = struct.unpack("<Q", raw[:8])[0]
fmt = "d" if m.group(1) == "Float64" else "f"
body = struct.unpack("<%d%s" % (size // struct.calcsize(fmt), fmt), raw[8:8 + size])
print(r["particles"], sum(1 for b in body if b == 0), r["wall_s"])
EOF
}
# The same case at PySPH's h = 1.3 Δx (the case's h_ratio = 1.5), where the case file still says 1.5.
H13=""
if grep -q '^h_ratio = 1.5$' cases/dam_break_2d.toml; then
    sed 's/^h_ratio = 1.5$/h_ratio = 1.3/' cases/dam_break_2d.toml >"$WORK/dam_break_2d.toml"
    H13=$WORK/dam_break_2d.toml
fi

echo "PySPH: warm-up run (compiles the generated code)" >&2
pysph --max-steps 1 >/dev/null 2>&1
# REPS rounds, each running every configuration once in turn, so that a slow spell of the machine
# falls on all of them alike; each configuration keeps its fastest round.
min() { awk -v a="$1" -v b="$2" 'BEGIN { print (a == "" || b + 0 < a + 0) ? b : a }'; }
pysph_s="" t64="" t64k="" t32="" t64h="" t64p="" t64hp=""
for r in $(seq 1 "$REPS"); do
    read -r pysph_n pysph_nf s < <(pysph_timed "$r")
    pysph_s=$(min "$pysph_s" "$s")
    read -r n64 nf64 s < <(pairsum "f64, C pair programs (round $r)" dam_break_2d --precision f64 --set boundary=dbc)
    t64=$(min "$t64" "$s")
    read -r _ _ s < <(PAIRSUM_NATIVE=cranelift pairsum "f64, Cranelift pair programs (round $r)" dam_break_2d \
        --precision f64 --set boundary=dbc)
    t64k=$(min "$t64k" "$s")
    read -r _ _ s < <(pairsum "f32, C pair programs (round $r)" dam_break_2d --precision f32 --set boundary=dbc)
    t32=$(min "$t32" "$s")
    read -r _ _ s < <(pairsum "f64, one evaluation per step (round $r)" dam_break_2d --precision f64 --set boundary=dbc \
        --set integrator=symplectic_pec)
    t64p=$(min "$t64p" "$s")
    if [ -n "$H13" ]; then
        read -r _ _ s < <(pairsum "f64, h = 1.3 dx (round $r)" "$H13" --precision f64 --set boundary=dbc)
        t64h=$(min "$t64h" "$s")
        read -r _ _ s < <(pairsum "f64, h = 1.3 dx, one evaluation per step (round $r)" "$H13" --precision f64 \
            --set boundary=dbc --set integrator=symplectic_pec)
        t64hp=$(min "$t64hp" "$s")
    fi
done

# Force evaluations in the timed part: PySPH's PEC integrator evaluates once per step, and its
# "Run took" includes the one evaluation before the first step (Solver.solve's initial_acceleration);
# pairsum's symplectic integrator evaluates twice per step (predictor and corrector).
ev_pysph=$((STEPS + 1))
ev_pairsum=$((2 * STEPS))
per() { awk -v t="$1" -v n="$2" -v s="$3" 'BEGIN { printf "%.2f", 1e6 * t / (n * s) }'; }
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a / b }'; }
pct() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.0f", 100 * a / b }'; }
fmt() { awk -v t="$1" 'BEGIN { printf "%.3f", t }'; }
p_pysph=$(per "$pysph_s" "$pysph_n" "$STEPS")
e_pysph=$(per "$pysph_s" "$pysph_n" "$ev_pysph")
f_pysph=$(per "$pysph_s" "$pysph_nf" "$STEPS")
row() { # label particles fluid time
    printf '%-34s %6s %6s %6s %8s %11s %14s %11s\n' "$1" "$2" "$3" "$STEPS" "$(fmt "$4")" \
        "$(per "$4" "$2" "$STEPS")" "$(per "$4" "$3" "$STEPS")" "$(per "$4" "$2" "$5")"
}
echo
echo "Dam break 2D, $STEPS steps, fastest of $REPS rounds, $THREADS threads, $(uname -m), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
echo "µs/p-step: per particle-step over all particles; µs/fluid-step: per fluid particle-step; µs/p-eval: per particle-evaluation"
# (a literal header: printf pads by bytes, and µ is two)
echo "                                    total  fluid  steps time [s]   µs/p-step  µs/fluid-step   µs/p-eval"
row "PySPH 1.0b2 WCSPH (OpenMP, f64)" "$pysph_n" "$pysph_nf" "$pysph_s" "$ev_pysph"
row "pairsum CPU f64, DBC, h = 1.5 dx" "$n64" "$nf64" "$t64" "$ev_pairsum"
row "pairsum CPU f64, DBC, Cranelift" "$n64" "$nf64" "$t64k" "$ev_pairsum"
row "pairsum CPU f32, DBC, h = 1.5 dx" "$n64" "$nf64" "$t32" "$ev_pairsum"
row "pairsum CPU f64, symplectic_pec" "$n64" "$nf64" "$t64p" "$STEPS"
[ -n "$t64h" ] && row "pairsum CPU f64, DBC, h = 1.3 dx" "$n64" "$nf64" "$t64h" "$ev_pairsum"
[ -n "$t64hp" ] && row "pairsum CPU f64, h = 1.3 dx, pec" "$n64" "$nf64" "$t64hp" "$STEPS"
echo
echo "evaluations timed: PySPH $ev_pysph ($STEPS PEC steps + the initial one), pairsum $ev_pairsum (2 per symplectic step)"
echo "PySPH / pairsum f64, per particle-step:        $(ratio "$p_pysph" "$(per "$t64" "$n64" "$STEPS")")×"
echo "PySPH / pairsum f64, per fluid particle-step:  $(ratio "$f_pysph" "$(per "$t64" "$nf64" "$STEPS")")×"
echo "PySPH / pairsum f64, per particle-evaluation:  $(ratio "$e_pysph" "$(per "$t64" "$n64" "$ev_pairsum")")×"
echo "PySPH / pairsum f32, per particle-step:        $(ratio "$p_pysph" "$(per "$t32" "$n64" "$STEPS")")×   (PySPH's CPU build is f64 only)"
echo "PySPH / pairsum f32, per particle-evaluation:  $(ratio "$e_pysph" "$(per "$t32" "$n64" "$ev_pairsum")")×"
if [ -n "$t64h" ]; then
    echo "PySPH / pairsum f64 at h = 1.3 Δx, per particle-step:       $(ratio "$p_pysph" "$(per "$t64h" "$n64" "$STEPS")")×"
    echo "PySPH / pairsum f64 at h = 1.3 Δx, per particle-evaluation: $(ratio "$e_pysph" "$(per "$t64h" "$n64" "$ev_pairsum")")×"
fi
echo "PySPH / pairsum f64 with one evaluation per step (symplectic_pec), per particle-step: $(ratio "$p_pysph" "$(per "$t64p" "$n64" "$STEPS")")×"
if [ -n "$t64hp" ]; then
    echo "PySPH / pairsum f64 at h = 1.3 Δx with one evaluation per step (PySPH's neighbours and evaluations), per particle-step: $(ratio "$p_pysph" "$(per "$t64hp" "$n64" "$STEPS")")×"
fi
echo "pairsum f64 / f32:                             $(ratio "$t64" "$t32")×"
echo "pairsum Cranelift / C pair code, f64:          $(ratio "$t64k" "$t64")×"
cat <<EOF

What differs (the compared figure is time per particle-step; read the per-evaluation line with it):
- Geometry: PySPH's own case (column 1 m × 2 m in a 4 m × 4 m tank, dx = 0.03 m, 4 boundary layers:
  $pysph_nf fluid + $((pysph_n - pysph_nf)) boundary) against pairsum's Martin & Moyce column (a × 2a, a = 57.15 mm,
  tank 8a long, walls 3a/20 thick) at Δx = $SPACING: $nf64 fluid + $((n64 - nf64)) wall. Fluid share: PySPH
  $(pct "$pysph_nf" "$pysph_n") %, pairsum $(pct "$nf64" "$n64") %; fluid particles are the costly ones on both sides.
- Smoothing length: PySPH h = 1.3 dx (about 21 neighbours within 2h in the bulk), recomputed every step
  from h = 1.3 (m/ρ)^(1/2) (Ferrari); pairsum h = 1.5 Δx (about 28), fixed. Same kernel: Wendland
  quintic (C2), support 2h. The h = 1.3 Δx rows run pairsum at PySPH's neighbour count; the last
  row does so with one evaluation per step as well, the configuration closest to PySPH's.
- Integrator: PySPH PECIntegrator with WCSPHStep: predict with the previous step's rates, one force
  evaluation, correct (1 neighbour evaluation, 2 particle stages per step); the neighbour bins are
  rebuilt once per step (compute_accelerations: nnps.update) and the adaptive time step is reduced in
  Python after every step. pairsum symplectic (DualSPHysics): force evaluation, predict to t + Δt/2,
  force evaluation, correct (2 neighbour evaluations, 2 particle stages per step). Neighbours come
  from Verlet lists (the case's [neighbours], skin 0.1 of the cut-off) rebuilt when a particle may
  have moved half the skin; the cell list behind them is built only then. Per particle-step
  pairsum does twice PySPH's neighbour passes.
- Per evaluation, PySPH (WCSPHScheme.get_equations, hg_correction, update_h, nu = 0, no delta-SPH):
  Group 1, per particle: TaitEOS on fluid, TaitEOSHGCorrection on boundary (ρ ≥ ρ0); Group 2, one
  neighbour loop per (destination, source) pair: fluid ← fluid: ContinuityEquation, MomentumEquation
  (pressure, Monaghan α = 0.1, β = 0, gravity, CFL reduction), XSPHCorrection (ε = 0.5);
  fluid ← boundary: ContinuityEquation, MomentumEquation; boundary ← fluid: ContinuityEquation
  (boundary ← boundary is never visited); Group 3, per particle: UpdateSmoothingLengthFerrari.
- Per evaluation, pairsum (models/wcsph_dbc.sph, pairsum plan dam_break_2d): one fused neighbour pass,
  fluid ← fluid|wall: continuity with Fourtakas density diffusion (δ = 0.1; a pow per fluid pair),
  momentum (pressure, Monaghan α = 0.1, laminar viscosity ν0 = 1e-6), the time step's viscous speed;
  wall ← fluid: continuity and viscous speed (wall–wall pairs are skipped in the search); then per particle:
  density floor (ρ ≥ ρ0 on walls, as PySPH's HG correction), Tait EOS, P/ρ². No XSPH.
- Boundary: both are dynamic boundary particles (wall density from continuity, fixed positions).
- Precision: PySPH's Cython/OpenMP build runs in f64 only; pairsum's f32 row has no PySPH counterpart.
EOF
