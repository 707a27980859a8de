# shellcheck shell=bash
# Feng, Nishita, Jin & Peng 2002, "B-spline free-form deformation of polygonal object as
# trimmed Bézier surfaces": Fig. 2a–d (the forward mapping warps the object, the identity
# initial volumes do not), Table 1 (surface degrees by the normal's class), Table 2 (sub-polygon
# and patch counts; the Fig. 7 object is the paper's own 12-triangle cube) and the bunny through
# a bent lattice (real data, when the data folder is found). Sourced by scripts/seed_figures.sh
# (see its contract). Uses python3 (standard library only) to bend lattices and compare meshes.
F="$OUT/feng2002"
mkdir -p "$F"

# bend_lattice IN OUT: move every control point of a lattice JSON by a smooth non-affine field
# (z += 0.6·e·u², x += 0.15·e·v², y += 0.1·e·w², u, v, w the normalised x, y, z; e the x
# extent), so no plane stays flat.
bend_lattice() {
    python3 - "$1" "$2" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
cp = j["control_points"]
xs = [p[0] for p in cp]; ys = [p[1] for p in cp]; zs = [p[2] for p in cp]
lo, hi, ylo, yhi, zlo, zhi = min(xs), max(xs), min(ys), max(ys), min(zs), max(zs)
e, mid = hi - lo, 0.5 * (lo + hi)
for p in cp:
    u, v, w = (p[0] - mid) / e, (p[1] - ylo) / (yhi - ylo), (p[2] - zlo) / (zhi - zlo)
    p[2] += 0.6 * e * u * u
    p[0] += 0.15 * e * v * v
    p[1] += 0.1 * e * w * w
json.dump(j, open(sys.argv[2], "w"))
PY
}

# max_move A.obj B.obj: the largest distance between corresponding vertices.
max_move() {
    python3 - "$1" "$2" <<'PY'
import sys
def verts(p):
    return [tuple(map(float, l.split()[1:4])) for l in open(p) if l.startswith("v ")]
a, b = verts(sys.argv[1]), verts(sys.argv[2])
assert len(a) == len(b)
print("%.6g" % max(sum((x - y) ** 2 for x, y in zip(p, q)) ** 0.5 for p, q in zip(a, b)))
PY
}

# Fig. 2a–d: a torus (marching cubes of the built-in model) deformed by the initial volume of
# degree 2×2×1 with a 4×4×2 lattice, as in the paper, by the accurate FFD (tessellated).
"$VOLMORPH" phantom torus --size 40 -o "$F/torus.nii.gz" >/dev/null
"$VOLMORPH" isosurface "$F/torus.nii.gz" --level 127 -o "$F/torus.obj" >/dev/null
R=(--view 30,55 --up z --size 300x240)
"$VOLMORPH" mesh render "$F/torus.obj" "${R[@]}" -o "$F/fig2a_object.png" >/dev/null
{
    echo "Feng 2002 Fig. 2: torus of $(grep -c '^f ' "$F/torus.obj") triangles, initial volume of degree 2x2x1, lattice 4x4x2"
    "$VOLMORPH" mesh info "$F/torus.obj" | grep '^bounds'
    echo "largest vertex displacement by the initial volume (vertex FFD):"
} > "$F/fig2_displacement.txt"
pics=(feng2002/fig2a_object.png)
for pair in b:forward c:uniform d:end-interpolating; do
    sub="${pair%%:*}" form="${pair#*:}"
    "$VOLMORPH" ffd "$F/torus.obj" --init "$form" --degree 2,2,1 --size 4,4,2 --mode accurate \
        -o "$F/fig2${sub}.obj" >/dev/null
    "$VOLMORPH" mesh render "$F/fig2${sub}.obj" "${R[@]}" -o "$F/fig2${sub}_${form}.png" >/dev/null
    "$VOLMORPH" ffd "$F/torus.obj" --init "$form" --degree 2,2,1 --size 4,4,2 --mode vertex \
        -o "$F/vertex.obj" >/dev/null
    echo "  Fig. 2$sub ($form): $(max_move "$F/torus.obj" "$F/vertex.obj")" >> "$F/fig2_displacement.txt"
    pics+=("feng2002/fig2${sub}_${form}.png")
done
fig feng2002 "Fig. 2a–d" "a: the object; b: deformed by the end-interpolating initial volume with evenly spaced control points reached by the forward mapping — warped (squeezed towards the centre planes) before any control point moves; c: the uniform volume with identity Jacobian; d: its end-interpolating conversion — both leave the object unchanged (degree 2×2×1, lattice 4×4×2; accurate FFD, tessellated)" \
    "${pics[@]}" feng2002/fig2_displacement.txt

# The paper's Fig. 7 object: a cube of 12 triangles.
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\nf 1 3 2\nf 2 3 4\nf 5 6 7\nf 6 8 7\nf 1 2 5\nf 2 6 5\nf 3 7 4\nf 4 7 8\nf 1 5 3\nf 3 5 7\nf 2 4 6\nf 4 8 6\n' > "$F/cube.obj"

# Table 1: one triangle per class of normal inside the unit cube, through a bent lattice around
# the cube of degree (ku, kv, kw) = (2, 2, 1) and (1, 2, 3); the degrees of the STEP surfaces
# against the table's.
T1="$F/table1_degrees.txt"
echo "Feng 2002 Table 1: degrees of the Bézier surfaces of one triangle per normal class (STEP B_SPLINE_SURFACE_WITH_KNOTS degrees, s x t)" > "$T1"
for deg in 2,2,1 1,2,3; do
    IFS=, read -r ku kv kw <<<"$deg"
    echo "lattice degrees (ku, kv, kw) = ($deg), 4x4x4 control points, bent:" >> "$T1"
    "$VOLMORPH" lattice init --mesh "$F/cube.obj" --degree "$deg" --size 4,4,4 -o "$F/tri_lat.json" >/dev/null
    bend_lattice "$F/tri_lat.json" "$F/tri_bent.json"
    if [ "$ku" -ge "$kv" ] && [ "$ku" -ge "$kw" ]; then
        general="$((kv + kw))×$((ku + kv + kw))"
    elif [ "$kv" -ge "$kw" ]; then
        general="$((ku + kw))×$((ku + kv + kw))"
    else
        general="$((ku + kv))×$((ku + kv + kw))"
    fi
    while IFS='|' read -r name tri want; do
        # shellcheck disable=SC2086 # the coordinates split into words on purpose
        printf 'v %s %s %s\n' ${tri//,/ } > "$F/tri.obj"
        echo "f 1 2 3" >> "$F/tri.obj"
        "$VOLMORPH" ffd "$F/tri.obj" --lattice "$F/tri_bent.json" --mode accurate -o "$F/tri.step" \
            </dev/null >/dev/null
        got=$(grep -o "B_SPLINE_SURFACE_WITH_KNOTS('',[0-9]*,[0-9]*" "$F/tri.step" | cut -d, -f2,3 \
            | sed 's/,/×/' | sort -u | tr '\n' ' ' || true)
        printf '  n = %-13s table %-6s measured %s\n' "$name" "$want" "${got:-planar}" >> "$T1"
    done <<CLASSES
(±1, 0, 0)|0.3,0.1,0.1 0.3,0.9,0.1 0.3,0.1,0.9|${kv}×${kw}
(0, ±1, 0)|0.1,0.3,0.1 0.1,0.3,0.9 0.9,0.3,0.1|${kw}×${ku}
(0, 0, ±1)|0.1,0.1,0.3 0.9,0.1,0.3 0.1,0.9,0.3|${ku}×${kv}
(0, ny, nz)|0.1,0.5,0.5 0.9,0.5,0.5 0.1,0.8,0.2|${ku}×$((kv + kw))
(nx, 0, nz)|0.5,0.1,0.5 0.5,0.9,0.5 0.8,0.1,0.2|${kv}×$((ku + kw))
(nx, ny, 0)|0.5,0.5,0.1 0.5,0.5,0.9 0.8,0.2,0.1|${kw}×$((ku + kv))
(nx, ny, nz)|0.9,0.2,0.1 0.2,0.9,0.3 0.3,0.1,0.8|${general}
CLASSES
done
fig feng2002 "Table 1" "surface degrees by the class of the normal, for lattices of degree 2×2×1 and 1×2×3: the table's s×t against the degrees written to STEP" \
    feng2002/table1_degrees.txt

# Table 2: sub-polygons and Bézier patches. Fig. 7's object (the 12-triangle cube, degree
# 2×2×2, lattice 4×4×4) is the paper's own; with real data, the bunny through the lattices of
# Figs. 8–13 (a different object than the paper's, so only our counts).
T2="$F/table2_counts.txt"
"$VOLMORPH" lattice init --mesh "$F/cube.obj" --degree 2,2,2 --size 4,4,4 -o "$F/cube_lat.json" >/dev/null
bend_lattice "$F/cube_lat.json" "$F/cube_bent.json"
counts() { # MESH LATTICE: "sub-polygons patches"
    "$VOLMORPH" ffd "$1" --lattice "$2" --mode accurate -o "$F/t2.step" \
        | awk '/^sub-polygons:/ {s=$2} /^Bézier patches:/ {p=$3} END {print s, p}'
}
read -r sp pp <<<"$(counts "$F/cube.obj" "$F/cube_bent.json")"
{
    echo "Feng 2002 Table 2 (new method): sub-polygons and Bézier patches"
    echo "Fig. 7  cube, 12 triangles, degree 2x2x2, lattice 4x4x4: volmorph $sp sub-polygons, $pp patches; paper 36, 24"
} > "$T2"
t2_files=(feng2002/table2_counts.txt)
if [[ -n "$DATA" && -f "$DATA/meshes/bunny.obj" ]]; then
    B="$DATA/meshes/bunny.obj"
    for row in "8 2,2,1 4,4,2" "9 2,2,1 5,5,2" "10 2,2,2 6,8,6" "11 2,2,2 6,9,3" "12 2,2,2 6,5,6" "13 2,2,2 7,3,6"; do
        read -r figno deg size <<<"$row"
        "$VOLMORPH" lattice init --mesh "$B" --degree "$deg" --size "$size" -o "$F/b_lat.json" >/dev/null
        bend_lattice "$F/b_lat.json" "$F/b_bent.json"
        read -r sp pp <<<"$(counts "$B" "$F/b_bent.json")"
        echo "Fig. $figno lattice: bunny, 3674 triangles, degree ${deg//,/x}, lattice ${size//,/x}: volmorph $sp sub-polygons, $pp patches" >> "$T2"
    done

    # The bunny through a bent 6×8×6 lattice of degree 2×2×2 (Fig. 10's configuration): the
    # accurate FFD (trimmed Bézier surfaces, tessellated) beside the vertex FFD.
    "$VOLMORPH" lattice init --mesh "$B" --degree 2,2,2 --size 6,8,6 -o "$F/b_lat.json" >/dev/null
    bend_lattice "$F/b_lat.json" "$F/b_bent.json"
    "$VOLMORPH" ffd "$B" --lattice "$F/b_bent.json" --mode accurate -o "$F/bunny.step" \
        --report "$F/bunny_accurate_report.json" >/dev/null
    "$VOLMORPH" ffd "$B" --lattice "$F/b_bent.json" --mode accurate -o "$F/bunny_acc.obj" >/dev/null
    "$VOLMORPH" ffd "$B" --lattice "$F/b_bent.json" --mode vertex -o "$F/bunny_vertex.obj" >/dev/null
    "$VOLMORPH" mesh render "$B" --view 20,15 --up y --size 320x320 -o "$F/bunny.png" >/dev/null
    "$VOLMORPH" mesh render "$F/bunny_vertex.obj" --view 20,15 --up y --size 320x320 -o "$F/bunny_vertex_ffd.png" >/dev/null
    "$VOLMORPH" mesh render "$F/bunny_acc.obj" --view 20,15 --up y --size 320x320 -o "$F/bunny_accurate_ffd.png" >/dev/null
    fig feng2002 "bunny FFD" "the Stanford bunny (3674 triangles) through a bent lattice of degree 2×2×2 with 6×8×6 control points: the input, the vertex FFD, and the accurate FFD (trimmed Bézier surfaces, STEP, here tessellated); counts and times in the report" \
        feng2002/bunny.png feng2002/bunny_vertex_ffd.png feng2002/bunny_accurate_ffd.png feng2002/bunny_accurate_report.json
fi
fig feng2002 "Table 2" "sub-polygons and Bézier patches of the new method: the paper's Fig. 7 cube reproduces its counts; bunny rows (with real data) for the lattices of Figs. 8–13" \
    "${t2_files[@]}"

# Keep the pictures and small text files only.
rm -f "$F"/*.obj "$F"/*.step "$F"/*.json.tmp "$F"/*.nii.gz "$F"/tri_lat.json "$F"/tri_bent.json \
    "$F"/cube_lat.json "$F"/cube_bent.json "$F"/b_lat.json "$F"/b_bent.json
