#!/usr/bin/env bash
# Fault injection on every output format the command line writes (volumes of every format
# including OME-Zarr stores, meshes, lattices, maps of every file form including displacement
# fields, PNG pictures, GIF and APNG animations, STEP, model JSON, scene projects):
# a write that fails (EIO/ENOSPC on write, EIO on the committing rename or link) or is killed
# (SIGKILL at a write or at the rename) must leave
# the old output or the complete new one, never a mix, and the next write must leave no
# temporary file behind.
#
#   scripts/fault_injection.sh [path/to/volmorph]
#
# Uses strace's fault injection (`-e inject=…`); skips cleanly (exit 0) without strace.
# Without an argument it builds the release binary. Prints one line per case and a closing
# "N passed, N failed" line; exits 1 if any case failed.
set -uo pipefail
cd "$(dirname "$0")/.."

if ! command -v strace >/dev/null 2>&1; then
    echo "fault_injection: strace not found; skipped (apt-get install strace)"
    exit 0
fi
if ! strace -f -e trace=none -e inject=write:error=EIO:when=65535 true >/dev/null 2>&1; then
    echo "fault_injection: strace cannot inject faults here (ptrace not permitted); skipped"
    exit 0
fi

VM="${1:-}"
if [ -z "$VM" ]; then
    # The whole workspace, so dependency features match the README's builds (no rebuilds).
    cargo build --release -q --workspace --bin volmorph || exit 1
    VM="${CARGO_TARGET_DIR:-target}/release/volmorph"
fi
VM="$(cd "$(dirname "$VM")" && pwd)/$(basename "$VM")"

WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
cd "$WORK" || exit 1

pass=0
fail=0
RUN=""

# Inputs: two volumes, a mesh and lattices that differ, so "old" and "new" outputs differ.
"$VM" phantom sphere --size 16 -o sphere.nii >/dev/null
"$VM" phantom torus --kind sdf --size 24 -o torus.nii >/dev/null
"$VM" isosurface sphere.nii --level 127 -o ball.obj >/dev/null
"$VM" lattice init --mesh ball.obj --degree 2,2,2 --size 4,4,4 -o mesh_lat.json >/dev/null
"$VM" lattice init sphere.nii --counts 5,5,5 -o la.json >/dev/null
"$VM" lattice init torus.nii --counts 6,6,6 -o lb.json >/dev/null
echo '{"version": 1, "kind": "identity"}' >id.json
echo '{"version": 1, "kind": "affine", "matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "offset": [1, 2, 3]}' >aff_a.json
echo '{"version": 1, "kind": "affine", "matrix": [[0.9, 0.1, 0], [0, 1.1, 0], [0, 0, 1]], "offset": [-1, 0, 2]}' >aff_b.json
printf 'my_model(x[3], a[1])\n{\n  my_model = 1.0 - sqrt(x[1]*x[1] + x[2]*x[2] + x[3]*x[3]);\n}\n' >ball.hf
printf 'my_model(x[3], a[1])\n{\n  my_model = 0.5 - max(abs(x[1]), max(abs(x[2]), abs(x[3])));\n}\n' >cube.hf
python3 - <<'PY' 2>/dev/null || cp mesh_lat.json mesh_lat2.json
import json
d = json.load(open("mesh_lat.json"))
d["control_points"][5][2] += 0.3
json.dump(d, open("mesh_lat2.json", "w"))
PY

# The command writing OUT with the "old" content, and with the "new" content, per format.
cmd_old() {
    local out="$1"
    # Matched on the file name: the reference outputs are written under ref/.
    case "$(basename "$out")" in
    field_*.mha) $RUN "$VM" map field aff_a.json --reference sphere.nii -o "$out" ;;
    *.nii | *.nii.gz | *.mha | *.mhd | *.nrrd | *.nhdr | *.vtk | *.vti | *.mgh | *.mgz | *.ome.zarr | *.raw)
        $RUN "$VM" phantom sphere --size 16 -o "$out" ;;
    *.gif | *.apng) $RUN "$VM" frep morph ball.hf cube.hf --frames 3 --size 32 -o "$out" ;;
    map_*.mat) $RUN "$VM" map compose aff_a.json id.json -o "$out" ;;
    *.obj | *.stl | *.ply | *.off) $RUN "$VM" isosurface sphere.nii --level 127 -o "$out" ;;
    lat_*.json | *.tfm | *.bxf) $RUN "$VM" lattice init sphere.nii --counts 5,5,5 -o "$out" ;;
    *.png) $RUN "$VM" slice sphere.nii --axis z -o "$out" ;;
    *.step) $RUN "$VM" ffd ball.obj --lattice mesh_lat.json --mode accurate -o "$out" ;;
    model_*.json) $RUN "$VM" nurbs fit sphere.nii --control-points 4 -o "$out" ;;
    map_*.json | map_*.tfm) $RUN "$VM" map compose la.json la.json -o "$out" ;;
    *.vmproj) $RUN "$VM" project new --phantom sphere --size 16 --lattice 4 -o "$out" ;;
    esac
}
cmd_new() {
    local out="$1"
    # Matched on the file name: the reference outputs are written under ref/.
    case "$(basename "$out")" in
    field_*.mha) $RUN "$VM" map field aff_b.json --reference sphere.nii -o "$out" ;;
    *.nii | *.nii.gz | *.mha | *.mhd | *.nrrd | *.nhdr | *.vtk | *.vti | *.mgh | *.mgz | *.ome.zarr | *.raw)
        $RUN "$VM" phantom torus --kind sdf --size 24 -o "$out" ;;
    *.gif | *.apng) $RUN "$VM" frep morph cube.hf ball.hf --frames 4 --size 32 -o "$out" ;;
    map_*.mat) $RUN "$VM" map compose aff_b.json id.json -o "$out" ;;
    *.obj | *.stl | *.ply | *.off) $RUN "$VM" isosurface torus.nii --level 0 --inside-below -o "$out" ;;
    lat_*.json | *.tfm | *.bxf) $RUN "$VM" lattice init torus.nii --counts 6,6,6 -o "$out" ;;
    *.png) $RUN "$VM" slice torus.nii --axis z -o "$out" ;;
    *.step) $RUN "$VM" ffd ball.obj --lattice mesh_lat2.json --mode accurate -o "$out" ;;
    model_*.json) $RUN "$VM" nurbs fit torus.nii --control-points 5 -o "$out" ;;
    map_*.json | map_*.tfm) $RUN "$VM" map compose lb.json la.json -o "$out" ;;
    *.vmproj) $RUN "$VM" project new --phantom torus --size 20 --lattice 5 -o "$out" ;;
    esac
}

# A comparable fingerprint of an output: its bytes, except that a header with a detached
# data file is read through volmorph (its data file's name differs per write) and a STEP
# file's header timestamp is left out.
fingerprint() {
    local f="$1"
    case "$f" in
    *.mhd | *.nhdr)
        "$VM" convert "$f" "fp_$$.nii" >/dev/null 2>&1 || { echo "unreadable"; return; }
        sha256sum <"fp_$$.nii" | cut -d' ' -f1
        rm -f "fp_$$.nii" ;;
    *.step) grep -v "FILE_NAME" "$f" | sha256sum | cut -d' ' -f1 ;;
    *.vmproj)
        # A project is a manifest and its data files: what volmorph reads from them (the
        # object list, and the volume, the lattice and the warped volume exported).
        {
            "$VM" project info "$f" 2>&1 | tail -n +2
            for o in 1:nii 2:json 3:nii; do
                "$VM" project export "$f" "${o%%:*}" -o "fp_$$.${o#*:}" >/dev/null 2>&1 &&
                    sha256sum <"fp_$$.${o#*:}"
                rm -f "fp_$$.${o#*:}"
            done
        } | sha256sum | cut -d' ' -f1 ;;
    *.ome.zarr)
        # A store is a folder: the names and bytes of every file in it.
        [ -d "$f" ] || { echo "missing"; return; }
        (cd "$f" && find . -type f | LC_ALL=C sort | xargs -d '\n' sha256sum) | sha256sum | cut -d' ' -f1 ;;
    *) sha256sum <"$f" | cut -d' ' -f1 ;;
    esac
}

# FI_OUTPUTS="m.obj p.png" restricts the run to some formats.
outputs="${FI_OUTPUTS:-v.nii v.nii.gz v.mha v.mhd v.nrrd v.nhdr v.vtk v.vti v.mgh v.mgz v.ome.zarr
v.raw m.obj m.stl m.ply m.off lat_l.json l.tfm l.bxf p.png a.gif a.apng s.step model_n.json
map_c.json map_c.tfm map_a.mat field_d.mha scene.vmproj}"

# Faults: failures and kills at the first, a middle and the committing system calls.
faults="write:error=EIO:when=1
write:error=ENOSPC:when=3
write:signal=KILL:when=2
write:signal=KILL:when=6
rename:error=EIO:when=1
renameat:error=EIO:when=1
renameat2:error=EIO:when=1
linkat:error=EIO:when=1
rename:signal=KILL:when=1
renameat:signal=KILL:when=1
renameat2:signal=KILL:when=1
linkat:signal=KILL:when=1"

for out in $outputs; do
    mkdir -p "ref"
    cmd_old "ref/$out" >/dev/null 2>&1 || { echo "FAIL $out: the old output cannot be written"; fail=$((fail + 1)); continue; }
    old_fp="$(fingerprint "ref/$out")"
    rm -rf ref && mkdir ref
    cmd_new "ref/$out" >/dev/null 2>&1 || { echo "FAIL $out: the new output cannot be written"; fail=$((fail + 1)); continue; }
    new_fp="$(fingerprint "ref/$out")"
    new_data="$(ls -A "ref/$out.data" 2>/dev/null | wc -l)"
    rm -rf ref
    while IFS= read -r fault; do
        sc="${fault%%:*}"
        dir="case_$$" && rm -rf "$dir" && mkdir "$dir" && cd "$dir" || exit 1
        ln -s ../sphere.nii ../torus.nii ../ball.obj ../mesh_lat.json ../mesh_lat2.json ../la.json ../lb.json \
            ../id.json ../aff_a.json ../aff_b.json ../ball.hf ../cube.hf . 2>/dev/null
        cmd_old "$out" >/dev/null 2>&1
        # Injected into the writing command only; syscalls this program never makes (e.g.
        # rename when it uses renameat) leave the write intact, which must then be complete.
        RUN="strace -f -qq -o /dev/null -e trace=$sc -e inject=$fault" cmd_new "$out" >/dev/null 2>&1
        got="$(fingerprint "$out" 2>/dev/null || echo missing)"
        verdict=""
        if [ "$got" != "$old_fp" ] && [ "$got" != "$new_fp" ]; then
            verdict="neither the old nor the new output ($got)"
        fi
        # The next write cleans what a killed one left.
        sleep 2.2
        cmd_new "$out" >/dev/null 2>&1
        left="$(ls -A | grep -E '^\.volmorph-.*\.partial$' || true)"
        if [ -n "$left" ]; then
            verdict="${verdict:+$verdict; }temporary files left after the next write: $left"
        fi
        case "$out" in
        *.vmproj)
            n="$(ls -A "$out.data" | wc -l)"
            [ "$n" = "$new_data" ] || verdict="${verdict:+$verdict; }$n files in $out.data after the next write, $new_data expected"
            ;;
        *.mhd | *.nhdr)
            n="$(ls -A | grep -c "^$out\.[0-9a-f]\{8\}\." || true)"
            [ "$n" = "1" ] || verdict="${verdict:+$verdict; }$n data files beside $out after the next write"
            ;;
        esac
        cd .. || exit 1
        rm -rf "$dir"
        if [ -z "$verdict" ]; then
            pass=$((pass + 1))
        else
            echo "FAIL $out [$fault]: $verdict"
            fail=$((fail + 1))
        fi
    done <<<"$faults"
    echo "ok   $out"
done

echo "fault injection: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
