#!/usr/bin/env bash
# Runs every test of pairsum. On a fresh Debian machine it first installs what the tests need:
# lavapipe (Debian's mesa-vulkan-drivers), which gives wgpu a Vulkan device on the CPU, so the GPU
# tests run without a GPU.
set -euo pipefail
cd "$(dirname "$0")/.."

as_root() {
    if [ "$(id -u)" = 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
        echo "scripts/test.sh: need root to run: $*" >&2; return 1; fi
}

if ! ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 || ! ldconfig -p | grep -q 'libvulkan.so.1'; then
    echo "scripts/test.sh: installing mesa-vulkan-drivers (lavapipe) for the GPU tests"
    export DEBIAN_FRONTEND=noninteractive
    as_root apt-get install -y --no-install-recommends mesa-vulkan-drivers libvulkan1 \
        || { as_root apt-get update && as_root apt-get install -y --no-install-recommends mesa-vulkan-drivers libvulkan1; }
fi

# The full-disk test (tests/faults.rs) mounts a tmpfs in a private namespace with util-linux's
# `unshare`; tests/scripts.rs runs scripts/shear_band.py with python3.
for tool in unshare:util-linux python3:python3; do
    if ! command -v "${tool%%:*}" >/dev/null; then
        echo "scripts/test.sh: installing ${tool#*:} for the tests"
        export DEBIAN_FRONTEND=noninteractive
        as_root apt-get install -y --no-install-recommends "${tool#*:}" \
            || { as_root apt-get update && as_root apt-get install -y --no-install-recommends "${tool#*:}"; }
    fi
done

# The runs across processes (tests/domains.rs) need Open MPI: its `mpirun` to start ranks, and
# its headers and libclang to build the `mpi` feature (the mpi crate's bindings). Open MPI refuses
# to run as root, which CI does, unless told.
if ! command -v mpirun >/dev/null || ! [ -e /usr/include/x86_64-linux-gnu/mpi/mpi.h -o -e /usr/include/mpi.h ] \
    || ! ldconfig -p | grep -Eq 'libclang(-[0-9.]+)?\.so'; then
    echo "scripts/test.sh: installing Open MPI (openmpi-bin, libopenmpi-dev) and libclang-dev for the MPI tests"
    export DEBIAN_FRONTEND=noninteractive
    as_root apt-get install -y --no-install-recommends openmpi-bin libopenmpi-dev libclang-dev \
        || { as_root apt-get update && as_root apt-get install -y --no-install-recommends openmpi-bin libopenmpi-dev libclang-dev; }
fi
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

# Everything is also logged, to close with one line that counts every test run.
log=$(mktemp)
trap 'rm -f "$log"' EXIT
logged() { "$@" 2>&1 | tee -a "$log"; return "${PIPESTATUS[0]}"; }

logged cargo test --workspace --features mpi "$@"

# With a filter or other arguments, only the tests asked for. Otherwise also what the suite above
# neither builds nor runs:
if [ $# -eq 0 ]; then
    # the portable lane loops (no AVX2), against the native pair code bit for bit;
    PAIRSUM_NO_WIDE_SIMD=1 logged cargo test --features mpi --test jit --test native
    # the criterion benchmarks, each run once in test mode (timings belong to `cargo bench`);
    logged cargo test --features mpi --benches
    # the coverage-guided fuzz targets (their own workspace, fuzz/), type-checked against today's
    # API: about 2.5 min on 2 cores, where a build, whose dependencies' features differ from the
    # test suite's, takes 7 (running them needs cargo-fuzz and a nightly toolchain: fuzz/README.md).
    logged cargo check --locked --manifest-path fuzz/Cargo.toml --target-dir target/fuzz-check
fi
awk '/^test result:/ { passed += $4; failed += $6 } END { printf "%d passed, %d failed\n", passed, failed }' "$log"
