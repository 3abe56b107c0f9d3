#!/usr/bin/env bash
# Short fuzzing of every target, for continuous integration: builds the targets (nightly
# toolchain, cargo-fuzz), runs each from the seed corpus for its budget (below;
# FUZZ_SECONDS=N gives every target N seconds), and fails on the first crash, timeout
# (30 s for one input) or use of more than 2 GiB.
# New inputs go to a scratch folder, not into the committed corpus.
#
# The targets build without AddressSanitizer (FUZZ_SANITIZER=address brings it back):
# what they feed is safe Rust, so a crash is a panic, an abort, a hang or memory, which
# libFuzzer sees by itself; without it the build takes a minute less and each target
# runs several times as many inputs in its budget. Optimisation level 1 builds in 3.5
# rather than 6 minutes here and runs the targets about as fast. Debug information is
# line tables, enough for a crash's backtrace to name file and line.
set -euo pipefail
cd "$(dirname "$0")"
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
sanitizer="${FUZZ_SANITIZER:-none}"
export CARGO_PROFILE_RELEASE_DEBUG=line-tables-only
export CARGO_PROFILE_RELEASE_OPT_LEVEL="${FUZZ_OPT_LEVEL:-1}"
"${fuzz[@]}" build -O -s "$sanitizer"
# FUZZ_BUILD_ONLY=1 stops here. FUZZ_START_FILE=PATH waits, once the targets are
# built, until that file exists: .ci/run builds the targets from its start and lets
# them fuzz once the tests are done.
if [ "${FUZZ_BUILD_ONLY:-0}" = 1 ]; then
    exit 0
fi
if [ -n "${FUZZ_START_FILE:-}" ]; then
    while [ ! -e "$FUZZ_START_FILE" ]; do sleep 1; done
fi
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
# Each target's budget (s). The readers that run a whole pipeline per input (a Rhai
# script, a run written and read back, a pipeline's values checked) run a few hundred
# to a few thousand inputs in 10 s; the file and message readers run tens of
# thousands to a million in 5. The slow ones start first, so that the two cores end
# together.
budgets="script:10 cli_roundtrip:10 pipeline_values:10 stl:5 obj:5 threemf:5 threemf_components:5 pipeline:5 machine:5 plugin_messages:5"
targets=""
for b in $budgets; do targets="$targets ${b%%:*}"; done
seconds_of() {
    if [ -n "${FUZZ_SECONDS:-}" ]; then echo "$FUZZ_SECONDS"; return; fi
    local b
    for b in $budgets; do
        if [ "${b%%:*}" = "$1" ]; then echo "${b#*:}"; return; fi
    done
}
# Each target is one process on one core: FUZZ_JOBS of them run at once (default: the
# machine's cores), and each one's report is printed when all are done.
jobs_max="${FUZZ_JOBS:-$(nproc)}"
fuzz_one() {
    local t="$1"
    mkdir -p "$scratch/$t"
    if "${fuzz[@]}" run -O -s "$sanitizer" "$t" "$scratch/$t" "corpus/$t" -- \
        -max_total_time="$(seconds_of "$t")" -timeout=30 -rss_limit_mb=2048 -print_final_stats=1 \
        2>"$scratch/$t.log"; then
        echo ok >"$scratch/$t.status"
    else
        echo failed >"$scratch/$t.status"
    fi
}
for t in $targets; do
    while [ "$(jobs -rp | wc -l)" -ge "$jobs_max" ]; do wait -n; done
    fuzz_one "$t" &
done
wait
for t in $targets; do
    echo "== fuzz $t ($(seconds_of "$t") s)"
    if [ "$(cat "$scratch/$t.status" 2>/dev/null)" != ok ]; then
        tail -n 60 "$scratch/$t.log"
        echo "fuzz target $t failed"
        exit 1
    fi
    grep -E "^stat::number_of_executed_units" "$scratch/$t.log" | sed "s/^/  $t: /"
done
