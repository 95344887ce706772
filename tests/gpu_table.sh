#!/usr/bin/env bash
# Issue 31's real-GPU table in one prepared script: what a session lent a GPU machine runs there, once, well
# inside its time. Not a test cargo runs. Two steps:
#
#   tests/gpu_table.sh prepare   here, on the build machine: release binaries of this checkout (flarelab,
#                                the gpu_timing and raygrid_timing examples, the ghosts_compute and raygrid_gpu
#                                test binaries), stripped and packed into .dev/bins.tgz; the Vulkan loader's
#                                Debian packages into .gl/; both ignored by git. Needs Debian's archive (apt).
#   tests/gpu_table.sh run       there (the device tool's `run`, carry [".gl", ".dev"], timeout_s 540): the
#                                zoom's 4K and 1080p paraxial and blended frames (GPU timestamps per pass), the
#                                ray grid 64 at 1920x1080 against the CPU, the compute twins' tests, the default
#                                bake and a whole 4K render on the GPU and on the CPU. Everything it prints also
#                                lands in $OUT/gpu_table.log. STEP_TIMEOUT=S limits each step (150 s).
#
# The figures the README's "On a real GPU" rows hold come from this output; the adapter's name is in it.
set -uo pipefail
cd "$(dirname "$0")/.."

prepare() {
    grep -qx '/.dev/' .git/info/exclude 2>/dev/null || echo '/.dev/' >>.git/info/exclude
    grep -qx '/.gl/' .git/info/exclude 2>/dev/null || echo '/.gl/' >>.git/info/exclude
    mkdir -p .dev .gl
    cargo build --release --bin flarelab || return 1
    cargo build --release -p flare_core --example gpu_timing --example raygrid_timing || return 1
    local tests
    tests=$(cargo test --release -p flare_core --test ghosts_compute --test raygrid_gpu --no-run \
        --message-format=json 2>/dev/null | grep -o '"executable":"[^"]*"' | cut -d'"' -f4) || return 1
    # Stripped and packed: what travels to the device machine may be 64 MiB at most.
    local bins
    bins=$(mktemp -d)
    cp target/release/flarelab target/release/examples/gpu_timing target/release/examples/raygrid_timing "$bins/"
    for t in $tests; do cp "$t" "$bins/$(basename "$t" | sed 's/-[0-9a-f]*$//')"; done
    strip "$bins"/*
    git rev-parse HEAD >"$bins/commit"
    rm -f .dev/*
    tar czf .dev/bins.tgz -C "$bins" . && rm -rf "$bins"
    # The loader and GL libraries the device machine lacks (the device tool's README).
    mkdir -p /tmp/amd64/partial
    local o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    # shellcheck disable=SC2086
    apt-get $o update -qq &&
        (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
    du -sh .dev .gl
}

run() {
    local out=${OUT:-/tmp/gpu_table}
    mkdir -p "$out"
    exec > >(tee "$out/gpu_table.log") 2>&1
    # The Vulkan loader, where the machine lacks it (the device tool's README).
    if ! ldconfig -p | grep -q libvulkan.so.1; then
        for f in .gl/*.deb; do dpkg -x "$f" /; done
        ldconfig
    fi
    if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
        export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    fi
    export FLARELAB_REQUIRE_GPU=1
    local d
    d=$(mktemp -d)
    tar xzf .dev/bins.tgz -C "$d" || return 1
    echo "build: $(cat "$d/commit")"; nvidia-smi -L 2>/dev/null; nproc
    local step
    step() { echo; echo "=== $* ($(date +%T))"; timeout "${STEP_TIMEOUT:-150}" "$@"; }
    # The default bake's LUT first (its whole command timed), then the frames that use it.
    step /usr/bin/time -f "bake whole command: %e s" $d/flarelab bake nikon_zoom_28_75mm -o /tmp/zoom.flut
    step /usr/bin/time -f "bake on the CPU, whole command: %e s" \
        $d/flarelab bake nikon_zoom_28_75mm --device cpu -o /tmp/zoom_cpu.flut
    step $d/gpu_timing nikon_zoom_28_75mm 3840 2160 compute frames=9
    # The same frame with every sprite on the base mask level (as before GhostMasks): the levels' gain.
    step $d/gpu_timing nikon_zoom_28_75mm 3840 2160 compute frames=9 base-mask
    step $d/gpu_timing nikon_zoom_28_75mm 3840 2160 /tmp/zoom.flut compute frames=9
    step $d/gpu_timing nikon_zoom_28_75mm 1920 1080 compute frames=9
    step $d/gpu_timing nikon_zoom_28_75mm 1920 1080 /tmp/zoom.flut compute frames=9
    step $d/gpu_timing nikon_zoom_28_75mm 3840 2160 /tmp/zoom.flut starburst compute frames=9
    # The CPU twin at 4K beside them (paraxial and blended, 16 threads there).
    step $d/gpu_timing nikon_zoom_28_75mm 3840 2160 frames=3
    step $d/raygrid_timing nikon_zoom_28_75mm 1920 1080 64 10
    step /usr/bin/time -f "render 4K GPU whole command: %e s" \
        $d/flarelab render nikon_zoom_28_75mm --size 3840x2160 --device gpu -o /tmp/z_gpu.exr
    step /usr/bin/time -f "render 4K CPU whole command: %e s" \
        $d/flarelab render nikon_zoom_28_75mm --size 3840x2160 --device cpu -o /tmp/z_cpu.exr
    step $d/ghosts_compute --test-threads=2
    step $d/raygrid_gpu --test-threads=2
    echo; echo "done $(date +%T)"
}

case "${1:-}" in
prepare) prepare ;;
run) run ;;
*)
    echo "usage: tests/gpu_table.sh prepare|run" >&2
    exit 2
    ;;
esac
