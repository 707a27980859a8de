#!/usr/bin/env bash
# Run every cargo-fuzz target for a bounded time: scripts/fuzz.sh [SECONDS_PER_TARGET]
#
# Needs a nightly toolchain (rustup toolchain install nightly) and cargo-fuzz
# (cargo install cargo-fuzz); skips cleanly (exit 0) when either is missing. Seeds each
# target's corpus with the test corpora of the readers. A crash, leak or timeout fails the
# run (exit 1) and leaves the reproducer under fuzz/artifacts/TARGET/.
set -euo pipefail
cd "$(dirname "$0")/.."
SECS="${1:-20}"
if ! rustup run nightly rustc --version >/dev/null 2>&1; then
    echo "fuzz: no nightly toolchain; skipped (rustup toolchain install nightly)"
    exit 0
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz: cargo-fuzz not installed; skipped (cargo install cargo-fuzz)"
    exit 0
fi
targets=$(sed -n 's/^name = "\(.*\)"$/\1/p' fuzz/Cargo.toml | grep -v '^volmorph-fuzz$')
cargo +nightly fuzz build -O --fuzz-dir fuzz
ok=0
bad=0
for t in $targets; do
    mkdir -p "fuzz/corpus/$t"
    seeds=()
    case "$t" in
    nifti | metaimage | nrrd | vtk) [ -d "crates/volume-io/tests/corpus/$t" ] && seeds+=("crates/volume-io/tests/corpus/$t") ;;
    esac
    if cargo +nightly fuzz run -O --fuzz-dir fuzz "$t" "fuzz/corpus/$t" "${seeds[@]}" -- \
        -max_total_time="$SECS" -rss_limit_mb=4096 -timeout=10 -print_final_stats=0 \
        >"fuzz/$t.log" 2>&1; then
        ok=$((ok + 1))
        echo "fuzz $t: ok (${SECS} s)"
    else
        bad=$((bad + 1))
        echo "fuzz $t: FAILED (see fuzz/$t.log and fuzz/artifacts/$t/)"
        tail -20 "fuzz/$t.log"
    fi
done
echo "fuzz targets: $ok clean, $bad crashed"
[ "$bad" -eq 0 ]
