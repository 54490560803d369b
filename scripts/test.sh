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

cargo test --workspace "$@"
