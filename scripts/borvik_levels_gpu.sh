#!/usr/bin/env bash
# The 3D Børvik plates at refined levels on a GPU, f32, on the shaped model's converging setting
# (ℓ = 2 mm, nonlocal hardening, visc 1/1, skin 0.1, r = 4, β = 0.5, p_spall = 6 GPa): the
# 12 mm plate at 399.6 m/s to 80 µs, the 8 mm plate at 298 m/s to 150 µs.
#   scripts/borvik_levels_gpu.sh OUT CASE [PAIRSUM] -- PLATE:RESOLUTION ...
# e.g. scripts/borvik_levels_gpu.sh out cases/borvik_perforation.toml -- 12:refined_571um 12:refined_500um
# CASE needs the resolutions named (the bundled case has refined_2mm to refined_571um; finer
# ones are its refined line at another dx, coarse_factor 4 mm / dx and band_spacing dx). The
# runs go one after another, each alone on the GPU; each writes histories.csv with its
# checkpoints (every 1000 steps), so a run cut short keeps its histories so far. Everything
# that comes back is packed into OUT/results.tgz after each run (a device lease returns only a
# few files): histories.csv, report.md, report.json and the log of every run. EXTRA adds
# options to every run (EXTRA="--max-steps 2" tries the script on lavapipe).
# Stop 102 ran 16 levels at once on an H200 for 600 s: the 0.4–0.5 mm levels of the 12 mm plate
# reached 16–19 µs of 80 (README.md, "On a real GPU").
set -uo pipefail
out=$(realpath -m "${1:?usage: scripts/borvik_levels_gpu.sh OUT CASE [PAIRSUM] -- PLATE:RESOLUTION ...}")
case_file=${2:?the case file}
bin=target/release/pairsum
[ "${3:-}" != "--" ] && bin=$3 && shift
shift 3 || true
mkdir -p "$out" /tmp/borvik_levels
setting=(--set model=models::ftlr19_perforation_shaped --set damage_length=2 --set visc_a=1 --set visc_b=1
  --set skin=0.1 --set nonlocal_hardening=1 --set shape_aspect=4 --set hourglass_visc=0.5 --set p_spall=6)
for level in "$@"; do
  plate=${level%%:*}; res=${level#*:}
  case $plate in
    12) speed=399.6; end=80 ;;
    8) speed=298; end=150 ;;
    *) echo "plate $plate: 12 or 8" >&2; exit 2 ;;
  esac
  tag=${plate}mm_${res}
  started=$(date +%s)
  mkdir -p /tmp/borvik_levels/$tag
  "$bin" run "$case_file" --backend gpu --precision f32 --resolution "$res" --out /tmp/borvik_levels/$tag --quiet \
    --force --checkpoint-every 1000 "${setting[@]}" --set thickness=$plate --set v_impact=$speed \
    --set end_time="$end us" ${EXTRA:-} >/tmp/borvik_levels/$tag/log.txt 2>&1 || true
  echo "$tag: $(( $(date +%s) - started )) s" >>/tmp/borvik_levels/times.txt
  (cd /tmp/borvik_levels && tar czf "$out/results.tgz" times.txt */histories.csv */report.md */report.json */log.txt 2>/dev/null)
done
