#!/bin/bash
# Strong scaling from one rank to two on this machine: each case for 100 steps on one process with
# one thread, one process with two, and `mpirun -n 2` (one thread a rank), twice each. Needs
# `cargo build --release --features mpi` and Open MPI. Output: docs/results/mpi_scaling/.
set -u
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
B="$(dirname "$0")/../../target/release/pairsum"
date
for case in "hypervelocity_impact --resolution 0.5mm" "dam_break_2d --resolution 0.7mm" "borvik_perforation --resolution ci"; do
  name=${case%% *}
  for round in 1 2; do
    RAYON_NUM_THREADS=1 $B run $case --max-steps 100 --out "${OUT:-/tmp/pairsum-mpi-bench}"/$name-1t --force --quiet --timing 2>&1 | grep "steps in" | head -1 | sed "s/^/single 1 thread: /"
    $B run $case --max-steps 100 --out "${OUT:-/tmp/pairsum-mpi-bench}"/$name-1 --force --quiet --timing 2>&1 | grep "steps in" | head -1 | sed "s/^/single 2 threads: /"
    mpirun -n 2 $B run $case --max-steps 100 --out "${OUT:-/tmp/pairsum-mpi-bench}"/$name-m2 --force --quiet --timing 2>&1 | grep "steps in\|rank 1 of" | head -2 | sed "s/^/mpirun -n 2: /"
  done
done
date
