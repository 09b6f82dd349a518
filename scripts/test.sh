#!/usr/bin/env bash
# The whole test suite: set-up, formatting and lints, unit + integration tests (independent
# readers included: Khronos validator, three.js, Blender, usd-core), and the reader self-test.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
# Each stage's start and the seconds since the run began, so a slow CI run shows where it went.
t0=$SECONDS
stage() { printf '[test] %4d s: %s\n' $((SECONDS - t0)) "$*" >&2; }
stage setup
bash scripts/setup.sh
stage "fmt, layers, links"
cargo fmt --all -- --check
bash scripts/layers.sh
bash scripts/check_links.sh
stage clippy
cargo clippy --workspace --all-targets --quiet -- -D warnings
# The GPU machine's build (docs/gpu.md: --no-default-features, no USD bridge) is compiled, not
# run; after clippy a check of the binary recompiles only our two crates.
stage "GPU-build check"
cargo check --no-default-features --bin garmentbake --quiet
stage "reader self-test"
bash tools/selftest.sh target/selftest >/dev/null
# Two shared cores: tests that spawn Blender or Node run alongside, torch stays on one thread.
stage "build the tests"
RUST_TEST_THREADS=2 cargo test --workspace --quiet --no-run
stage "unit and integration tests"
RUST_TEST_THREADS=2 cargo test --workspace --quiet
stage done
echo "all tests passed"
