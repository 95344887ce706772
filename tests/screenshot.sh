#!/usr/bin/env bash
# Starts the app (release build) under Xvfb, saves a screenshot and prints the drag bench's frame times at
# 1280x720: the app smoke tests, run on an optimised build for a person to look at.
# Needs xvfb and xauth (`.ci/run` installs them). The screenshot lands in target/release/../tmp.
set -euo pipefail
cd "$(dirname "$0")/.."
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
cargo test --release --test app_smoke -- --nocapture --test-threads 1 2>&1 | grep -E "screenshot:|drag bench:|test result|SKIPPED|panicked"
