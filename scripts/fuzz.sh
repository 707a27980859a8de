#!/usr/bin/env bash
# Run every cargo-fuzz target for a bounded time:
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]
#
# Works with the stable toolchain: cargo-fuzz asks rustc for unstable flags (sanitizer
# coverage instrumentation), which RUSTC_BOOTSTRAP=1 allows on a stable compiler, so no nightly
# toolchain is needed. Needs cargo-fuzz: with FUZZ_INSTALL=1 (what .ci/run sets) it is
# installed when missing (`cargo install cargo-fuzz --locked`); otherwise the script skips
# cleanly (exit 0) without it.
#
# Environment:
#   FUZZ_SANITIZER  none (default) or address. The workspace forbids unsafe code, so the
#                   faults fuzzing finds are panics, hangs and runaway allocations, which need
#                   no sanitizer; `address` also checks the dependencies' unsafe code, at
#                   about 2x the build and run time.
#   FUZZ_JOBS       parallel fuzzing processes per target (default 1).
#   FUZZ_PARALLEL   targets fuzzed at the same time (default: the number of cores). Each
#                   libFuzzer process is single-threaded, so on 2 cores two targets run side
#                   by side in the time of one.
#   FUZZ_BUILD_ONLY 1: install cargo-fuzz when asked (FUZZ_INSTALL=1), build every target,
#                   and stop without fuzzing (what .ci/run starts in the background early, so
#                   the instrumented build overlaps the sections that leave cores idle).
#
# Each target starts from its saved corpus (fuzz/corpus/TARGET, not in git) plus the seed
# files of the readers' test corpora. Builds with debug assertions (overflow checks on).
# A crash, a leak, a timeout (10 s for one input) or an allocation beyond -rss_limit_mb fails
# the run (exit 1) and leaves the reproducer under fuzz/artifacts/TARGET/; replay it with
#   RUSTC_BOOTSTRAP=1 cargo fuzz run -O -a -s none --fuzz-dir fuzz TARGET fuzz/artifacts/TARGET/crash-…
set -euo pipefail
cd "$(dirname "$0")/.."
SECS="${1:-20}"
shift || true
SAN="${FUZZ_SANITIZER:-none}"
JOBS="${FUZZ_JOBS:-1}"

if ! cargo fuzz --version >/dev/null 2>&1; then
    if [ "${FUZZ_INSTALL:-0}" = "1" ]; then
        echo "fuzz: installing cargo-fuzz"
        start=$(date +%s)
        cargo install cargo-fuzz --locked --quiet
        echo "fuzz: cargo-fuzz installed in $(($(date +%s) - start)) s"
    else
        echo "fuzz: cargo-fuzz not installed; skipped (cargo install cargo-fuzz, or FUZZ_INSTALL=1)"
        exit 0
    fi
fi
export RUSTC_BOOTSTRAP=1
FLAGS=(-O -a -s "$SAN" --fuzz-dir fuzz)

all=$(sed -n 's/^name = "\(.*\)"$/\1/p' fuzz/Cargo.toml | grep -v '^volmorph-fuzz$')
targets="${*:-$all}"

start=$(date +%s)
cargo fuzz build "${FLAGS[@]}"
echo "fuzz: targets built in $(($(date +%s) - start)) s"
if [ "${FUZZ_BUILD_ONLY:-0}" = "1" ]; then
    exit 0
fi
PARALLEL="${FUZZ_PARALLEL:-$(nproc)}"

# Seed files per target: the test corpora of the readers and peer-written fixtures.
seeds_of() {
    local c=crates/volume-io/tests/corpus
    case "$1" in
    nifti) ls "$c"/nifti/* "$c"/peers/*.nii "$c"/peers/*.nii.gz ;;
    metaimage | nrrd | vtk) ls "$c/$1"/* ;;
    vti) ls "$c"/peers/*.vti ;;
    mgh) ls "$c"/peers/*.mgz ;;
    dicom | dicom_series) ls "$c"/peers/*.dcm "$c"/peers/sitk_ct_series/* ;;
    esac 2>/dev/null || true
}

# One target: fuzz it from its corpus and write "ok" or "FAILED" into STATUS_DIR/TARGET.
fuzz_one() {
    local t="$1" corpus="fuzz/corpus/$1"
    mkdir -p "$corpus"
    for f in $(seeds_of "$t"); do
        [ -f "$f" ] && cp -n "$f" "$corpus/seed-$(basename "$f")"
    done
    # -jobs makes libFuzzer fork workers logging to fuzz-N.log files: only when asked for.
    local par=()
    if [ "$JOBS" -gt 1 ]; then
        par=(-jobs="$JOBS" -workers="$JOBS")
    fi
    if cargo fuzz run "${FLAGS[@]}" "$t" "$corpus" -- \
        -max_total_time="$SECS" -rss_limit_mb=2048 -timeout=10 "${par[@]}" \
        -print_final_stats=1 >"fuzz/$t.log" 2>&1; then
        local runs
        runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "fuzz/$t.log" | tail -1)
        echo "fuzz $t: ok (${SECS} s, ${runs:-?} inputs)"
        echo ok >"$STATUS_DIR/$t"
    else
        echo "fuzz $t: FAILED (see fuzz/$t.log and fuzz/artifacts/$t/)"
        tail -30 "fuzz/$t.log"
        echo FAILED >"$STATUS_DIR/$t"
    fi
}

STATUS_DIR=$(mktemp -d)
trap 'rm -rf "$STATUS_DIR"' EXIT
start=$(date +%s)
running=0
for t in $targets; do
    if [ "$running" -ge "$PARALLEL" ]; then
        wait -n || true
        running=$((running - 1))
    fi
    fuzz_one "$t" &
    running=$((running + 1))
done
wait
ok=0
bad=0
for t in $targets; do
    if [ "$(cat "$STATUS_DIR/$t" 2>/dev/null)" = ok ]; then
        ok=$((ok + 1))
    else
        bad=$((bad + 1))
    fi
done
echo "fuzz: $ok passed, $bad failed ($PARALLEL at a time, $(($(date +%s) - start)) s)"
[ "$bad" -eq 0 ]
