#!/bin/bash
# Weak scaling from one rank to two on this machine: each case at a spacing that gives about half
# its particles on one process with one thread, then at the full count on `mpirun -n 2` (one
# thread a rank), 100 steps, twice each. Efficiency: the first's time per step over the second's.
# One process with two threads at the full count is beside them: what two cores give without MPI.
# Needs `cargo build --release --features mpi` and Open MPI. Output: docs/results/mpi_scaling/.
set -u
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
B="$(dirname "$0")/../../target/release/pairsum"
OUT="${OUT:-/tmp/pairsum-mpi-weak}"
date
for pair in "hypervelocity_impact 0.63mm 0.5mm" "dam_break_2d 0.99mm 0.7mm"; do
  set -- $pair
  for round in 1 2; do
    RAYON_NUM_THREADS=1 $B run $1 --resolution $2 --max-steps 100 --out "$OUT/$1-half" --force --quiet --timing 2>&1 | grep "steps in" | head -1 | sed "s/^/1 rank, $2: /"
    RAYON_NUM_THREADS=1 mpirun -n 2 $B run $1 --resolution $3 --max-steps 100 --out "$OUT/$1-full" --force --quiet --timing 2>&1 | grep "steps in" | head -1 | sed "s/^/2 ranks, $3: /"
    $B run $1 --resolution $3 --max-steps 100 --out "$OUT/$1-threads" --force --quiet --timing 2>&1 | grep "steps in" | head -1 | sed "s/^/1 process, 2 threads, $3: /"
  done
done
date
