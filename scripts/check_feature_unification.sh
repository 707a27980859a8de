#!/usr/bin/env bash
# Fails when a package that maturin builds alone (the Python extension, python/) would resolve
# a shared dependency with other features than `cargo test --release --workspace` does. Such a
# difference makes the wheel build recompile most of the workspace (seen: 866 s instead of
# about 80 s in CI). The fix is to list the dependency, with the features this script prints,
# under "Feature unification with the workspace" in python/Cargo.toml.
set -euo pipefail
cd "$(dirname "$0")/.."
features() {
    cargo tree --offline "$@" -f '{p}|{f}' --prefix none 2>/dev/null ||
        cargo tree "$@" -f '{p}|{f}' --prefix none
}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
features -p volmorph-python -e normal,build | sed 's/ (\*)//;s/ (proc-macro)//' | sort -u >"$tmp/alone"
features --workspace -e normal,build,dev | sed 's/ (\*)//;s/ (proc-macro)//' | sort -u >"$tmp/workspace"
drift=$(comm -23 "$tmp/alone" "$tmp/workspace")
if [ -n "$drift" ]; then
    echo "python/ alone resolves these dependencies (package|features) unlike the workspace:" >&2
    echo "$drift" >&2
    echo "the workspace has:" >&2
    for p in $(echo "$drift" | cut -d'|' -f1 | cut -d' ' -f1); do grep "^$p v" "$tmp/workspace" >&2; done
    exit 1
fi
echo "python/ resolves its dependencies with the workspace's features"
