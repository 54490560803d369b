#!/usr/bin/env bash
# The WGSL backend on a real GPU against the CPU backend on the same machine, in one run:
#   benches/gpu/run.sh OUT [PAIRSUM]
# For each case below, two GPU runs of different step counts (their difference is the cost of a
# step, without set-up, shader compilation or the first output) and one CPU run of the shorter count
# on every core, all f32. Each run's report.json and histories.csv go to OUT as
# <case>_<resolution>.<run>.report.json and .histories.csv;
# benches/gpu/summarise.py OUT prints ns per particle-step, the GPU/CPU ratio and the largest
# relative difference of the probes between the backends.
# PAIRSUM is the binary (default target/release/pairsum). Set SKIP_CPU=1 to run the GPU only, and
# ONLY="pysph_impact3d_0.25mm dam_break_2d_0.1mm" to run only those.
set -uo pipefail
out=${1:?usage: benches/gpu/run.sh OUT [PAIRSUM]}
bin=${2:-target/release/pairsum}
mkdir -p "$out"
{ nvidia-smi --query-gpu=name,memory.total,clocks.max.memory --format=csv 2>/dev/null; nproc; } >"$out/machine.txt"
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT

# case resolution short long end_time cpu|- [arguments...]: the end time past the longer run, so
# --max-steps ends both; `cpu` also runs the shorter count on the CPU backend. The step counts are
# far enough apart that the difference of the two stepping loops' times (a few seconds) stands
# well above what they move between runs.
runs=(
  "sod_shock_tube ci 200 800 0.2 cpu"
  "pysph_impact3d 0.5mm 100 500 1e-4 cpu"
  "pysph_impact3d 0.25mm 40 440 1e-4 cpu"
  "pysph_impact3d 0.125mm 20 120 1e-4 -"
  "dam_break_2d 0.1mm 100 700 0.28 cpu"
  "dam_break_3d gpu 50 350 0.11 - --set integrator=symplectic_pec"
)

one() { # case resolution backend steps name end_time [arguments...]
  local at="$out/$1_$2.$5"
  local start=$(date +%s%N)
  timeout 300 "$bin" run "$1" --resolution "$2" --backend "$3" --precision f32 --max-steps "$4" --end-time "$6" \
    --out "$scratch/run" --quiet "${@:7}" >"$at.stdout.txt" 2>&1
  echo "exit $? total_ms $(( ($(date +%s%N) - start) / 1000000 ))" >>"$at.stdout.txt"
  cp "$scratch/run/report.json" "$at.report.json" 2>/dev/null
  cp "$scratch/run/histories.csv" "$at.histories.csv" 2>/dev/null
  rm -rf "$scratch/run"
  tail -1 "$at.stdout.txt"
}

for r in "${runs[@]}"; do
  read -r case res short long end cpu extra <<<"$r"
  if [ -n "${ONLY:-}" ] && [[ " $ONLY " != *" ${case}_${res} "* ]]; then continue; fi
  # shellcheck disable=SC2086 # the extra arguments are words
  one "$case" "$res" gpu "$short" gpu_short "$end" $extra
  # shellcheck disable=SC2086
  one "$case" "$res" gpu "$long" gpu_long "$end" $extra
  if [ "$cpu" = cpu ] && [ -z "${SKIP_CPU:-}" ]; then
    # shellcheck disable=SC2086
    one "$case" "$res" cpu "$short" cpu_short "$end" $extra
  fi
done
