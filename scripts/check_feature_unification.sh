#!/usr/bin/env bash
# Fails when two builds that should share their compiled dependencies would resolve a shared
# dependency with different features, so that everything above it compiles twice:
#   * the demo's build (`cargo run --release -- demo`: the command-line tool, the workspace's
#     default member, without dev-dependencies) against the test build
#     (`cargo test --release --workspace`);
#   * the Python extension built alone, as maturin does (`-p volmorph-python`), against the
#     test build (seen before the fix: the wheel build took 866 s instead of about 80 s).
# The fix is to list the dependency, with the features printed here, under "Feature
# unification with the workspace" in crates/cli/Cargo.toml (demo) or python/Cargo.toml
# (wheel).
#
# Compares cargo's unit graphs (`--unit-graph`, unstable, allowed on stable by
# RUSTC_BOOTSTRAP=1 as scripts/fuzz.sh does); nothing is compiled.
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
graph() {
    local out="$1"
    shift
    RUSTC_BOOTSTRAP=1 cargo "$@" --release --unit-graph -Z unstable-options >"$out"
}
graph "$tmp/test.json" test --workspace --no-run
graph "$tmp/demo.json" build -p volmorph-cli --bins
graph "$tmp/wheel.json" build -p volmorph-python --lib
python3 - "$tmp" <<'PY'
import json, sys

def features(path):
    units = {}
    for u in json.load(open(path))["units"]:
        if u["mode"] != "build" or u["target"]["kind"] == ["custom-build"]:
            continue
        if not u["pkg_id"].startswith("registry+"):
            continue
        key = (u["pkg_id"].split("#")[-1], u["target"]["name"], u.get("platform"))
        units.setdefault(key, set()).add(tuple(sorted(u["features"])))
    return units

tmp = sys.argv[1]
test = features(f"{tmp}/test.json")
bad = 0
for name in ("demo", "wheel"):
    for key, feats in sorted(features(f"{tmp}/{name}.json").items()):
        if key in test and feats != test[key]:
            bad += 1
            print(f"{name} build: {key[0]} has features {sorted(feats)}, "
                  f"the test build {sorted(test[key])}", file=sys.stderr)
if bad:
    sys.exit(1)
print("the demo, wheel and test builds resolve shared dependencies alike")
PY
