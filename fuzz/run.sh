#!/usr/bin/env bash
# Runs one fuzz target on its seed corpus (fuzz/make_seeds.py) for SECONDS (default 600), one job,
# no sanitizer (safe Rust: the readers are fuzzed for panics, hangs and memory blow-ups), debug
# assertions and overflow checks on. Prints libFuzzer's log; the corpus grows in fuzz/corpus/TARGET.
# usage: bash fuzz/run.sh TARGET [SECONDS]      (from the repository root; cargo-fuzz, nightly)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
target=$1
seconds=${2:-600}
[ -d "fuzz/corpus/$target" ] || .venv/bin/python fuzz/make_seeds.py
exec cargo +nightly fuzz run -s none -a "$target" "fuzz/corpus/$target" -- \
    -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1
