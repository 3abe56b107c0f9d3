#!/usr/bin/env bash
# Short fuzzing of every target, for continuous integration: builds the targets (nightly
# toolchain, cargo-fuzz), runs each for FUZZ_SECONDS (default 15) from the seed corpus,
# and fails on the first crash, leak, timeout (30 s for one input) or use of more than
# 2 GiB. New inputs go to a scratch folder, not into the committed corpus.
set -euo pipefail
cd "$(dirname "$0")"
seconds="${FUZZ_SECONDS:-15}"
command -v cargo-fuzz >/dev/null 2>&1 || cargo install cargo-fuzz --locked --quiet
# The sanitizer flags need a nightly compiler; without one, the stable compiler is
# told to accept them.
if rustup run nightly rustc --version >/dev/null 2>&1; then
    fuzz=(cargo +nightly fuzz)
else
    echo "note: no nightly toolchain; building the fuzz targets with the stable one"
    export RUSTC_BOOTSTRAP=1
    fuzz=(cargo fuzz)
fi
"${fuzz[@]}" build -O
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
targets="stl obj threemf pipeline script cli_roundtrip pipeline_values plugin_messages"
for t in $targets; do
    mkdir -p "$scratch/$t"
    echo "== fuzz $t (${seconds} s)"
    "${fuzz[@]}" run -O "$t" "$scratch/$t" "corpus/$t" -- \
        -max_total_time="$seconds" -timeout=30 -rss_limit_mb=2048 -print_final_stats=1 \
        2>"$scratch/$t.log" || { tail -n 60 "$scratch/$t.log"; echo "fuzz target $t failed"; exit 1; }
    grep -E "^stat::number_of_executed_units" "$scratch/$t.log" | sed "s/^/  $t: /"
done
