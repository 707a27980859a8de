# shellcheck shell=bash
# Savchenko & Pasko 1998, "Transformation of functionally defined shapes by extended space
# mappings": Figs. 2, 3, 5, 6–7 (CT head, real data), 8, 9, 10–12 and the reconstruction from
# scattered points (§4.1.1), through `volmorph frep map` and `volmorph frep points`. Sourced by
# scripts/seed_figures.sh (see its contract).
S="$OUT/savchenko_pasko"
W="$S/work"
mkdir -p "$S" "$W"
P=(--size 288)

# The constructive solid of Figs. 2, 8 and 9: a block and a ball united by R-functions, a
# cylinder drilled through, edges blended.
cat > "$W/solid.hf" <<'EOF'
solid(x[3], a[1])
{
  array c[3]; array v[3];
  c = [0.3, 0.3, 0.3]; v = [-0.8, -0.8, -0.6];
  blk = hfBlock(x, v, 1.3, 1.3, 1.0);
  ball = hfSphere(x, c, 0.55);
  hole = 0.25^2 - (x[1] + 0.3)^2 - (x[2] + 0.3)^2;
  solid = hfBlendUni(blk, ball, 0.2, 1, 1) \ hole;
}
EOF
B=(--bounds=-1.1,1.1)
echo '{"version": 1, "mappings": []}' > "$W/none.json"
"$VOLMORPH" frep map "$W/solid.hf" --mapping "$W/none.json" -o "$S/fig02a_initial.png" "${B[@]}" "${P[@]}" >/dev/null

# Fig. 2b: pinching (a control point inside the solid pulls the surface in) and pricking (a
# point outside pulls a spike out); Fig. 2c: scratching with an elongated elliptic area.
cat > "$W/prick.json" <<'EOF'
{"version": 1, "mappings": [{"kind": "control-points", "points": [
  {"at": [0.5, -0.8, 0.1], "radius": 0.35},
  {"at": [0.3, 0.3, 1.05], "radius": 0.3},
  {"at": [-0.55, -0.3, 0.15], "radius": 0.4}]}]}
EOF
"$VOLMORPH" frep map "$W/solid.hf" --mapping "$W/prick.json" -o "$S/fig02b_pinch_prick.png" "${B[@]}" "${P[@]}" >/dev/null
cat > "$W/scratch.json" <<'EOF'
{"version": 1, "mappings": [{"kind": "control-points", "points": [
  {"at": [0.0, -0.62, 0.2], "axes": [[0.6, 0, 0], [0, 0.12, 0], [0, 0, 0.06]]},
  {"at": [0.5, 0.0, 0.32], "axes": [[0.05, 0, 0], [0, 0.5, 0], [0, 0, 0.1]]}]}]}
EOF
"$VOLMORPH" frep map "$W/solid.hf" --mapping "$W/scratch.json" -o "$S/fig02c_scratch.png" "${B[@]}" "${P[@]}" >/dev/null
fig savchenko_pasko "Fig. 2" "local function mappings by control points (Eq. 11): a initial solid (R-function union, blend, difference); b pinching (point inside) and pricking (points outside); c scratching with elliptic areas of influence" \
    savchenko_pasko/fig02a_initial.png savchenko_pasko/fig02b_pinch_prick.png savchenko_pasko/fig02c_scratch.png

# Fig. 3: a block deformed by convolution along a curve inside it (Eq. 12, Simpson's rule).
cat > "$W/block.hf" <<'EOF'
block(x[3], a[1]) { array v[3]; v = [-0.8, -0.8, -0.5]; block = hfBlock(x, v, 1.6, 1.6, 1.0); }
EOF
cat > "$W/spiral.json" <<'EOF'
{"version": 1, "mappings": [{"kind": "convolution", "a": 0.3, "intervals": 128, "curve":
  {"type": "helix", "center": [0, 0, 0.2], "radius": 0.45, "pitch": 0.0001, "turns": 1.0}}]}
EOF
"$VOLMORPH" frep map "$W/block.hf" --mapping "$W/spiral.json" -o "$S/fig03_spiral.png" --bounds=-1.1,1.1 "${P[@]}" --view 30,50 >/dev/null
fig savchenko_pasko "Fig. 3" "function mapping controlled by a parametric curve: convolution deformation of a block (Eq. 12) along a circle 0.3 below its top; the displacement is weighted by f on the curve, so the sweep is a shallow dent and rounding of the top" \
    savchenko_pasko/fig03_spiral.png

# Fig. 5: one control point of a set-theoretic "clock" displaced (red arrow in the paper),
# the space mapped by volume splines interpolating the x, y and z displacements (Eq. 15–16).
cat > "$W/clock.hf" <<'EOF'
clock(x[3], a[1])
{
  array c[3];
  c = [0, 0, 0];
  disk = hfCylinderZ(x, c, 1.0) & (0.08 - abs(x[3]));
  rim = hfTorusZ(x, c, 1.0, 0.08);
  hand = min(0.05 - abs(x[2]), min(x[1] + 0.05, 0.7 - x[1]));
  hand = min(hand, 0.04 - abs(x[3] - 0.1));
  clock = (disk | rim) | hand;
}
EOF
cat > "$W/droop.json" <<'EOF'
{"version": 1, "mappings": [{"kind": "handles",
  "sources": [[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 0.6], [-0.5, 0, -0.6]],
  "targets": [[1.15, 0, -0.7], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 0.6], [-0.5, 0, -0.6]]}]}
EOF
"$VOLMORPH" frep map "$W/clock.hf" --mapping "$W/none.json" -o "$S/fig05a_clock.png" --bounds=-1.3,1.3 "${P[@]}" >/dev/null
"$VOLMORPH" frep map "$W/clock.hf" --mapping "$W/droop.json" -o "$S/fig05b_drooping.png" --bounds=-1.3,1.3 "${P[@]}" >/dev/null
fig savchenko_pasko "Fig. 5" "3D coordinate space mapping with volume splines: a a set-theoretic clock; b the clock after one control point on its rim moved down (after Dali)" \
    savchenko_pasko/fig05a_clock.png savchenko_pasko/fig05b_drooping.png

# Figs. 6–7: the CT head of the data folder as an F-rep (vmVolume, trilinear, skin at −300 HU).
if [[ -n "$DATA" && -f "$DATA/volumes/cranium_ct.nii.gz" ]]; then
    ln -sf "$DATA/volumes/cranium_ct.nii.gz" "$W/cranium_ct.nii.gz"
    cat > "$W/head.hf" <<'EOF'
head(x[3], a[1]) { head = vmVolume("cranium_ct.nii.gz", x, -300, "linear"); }
EOF
    HB=(--bounds=-250,-250,-5,5,-60,165 --size 288 --view -70,10)
    "$VOLMORPH" --allow-external-data frep map "$W/head.hf" --mapping "$W/none.json" -o "$S/fig06a_head.png" "${HB[@]}" >/dev/null
    # 12 control points: the mouth corners pulled up and out, the rest of the head held.
    cat > "$W/smile.json" <<'EOF'
{"version": 1, "mappings": [{"kind": "handles", "smoothing": 0,
  "sources": [[-107, -212, 12], [-139, -212, 12], [-122.5, -232.6, 36], [-122.5, -208, 90],
              [-86, -191, 45], [-163, -195, 45], [-122, -60, 80], [-122, -130, 150],
              [-122.5, -221, 2], [-60, -150, 60], [-185, -150, 60], [-122.5, -215, 16]],
  "targets": [[-100, -214, 26], [-146, -214, 26], [-122.5, -232.6, 36], [-122.5, -208, 90],
              [-86, -191, 45], [-163, -195, 45], [-122, -60, 80], [-122, -130, 150],
              [-122.5, -221, 2], [-60, -150, 60], [-185, -150, 60], [-122.5, -215, 17]]}]}
EOF
    "$VOLMORPH" --allow-external-data frep map "$W/head.hf" --mapping "$W/smile.json" -o "$S/fig06b_expression.png" "${HB[@]}" >/dev/null
    fig savchenko_pasko "Fig. 6" "facial expression by coordinate space mapping with 12 control points (volume spline) applied to the volumetric head: a the CT head (cranium_ct, trilinear vmVolume, −300 HU); b the mouth corners raised" \
        savchenko_pasko/fig06a_head.png savchenko_pasko/fig06b_expression.png
    # Fig. 7: a slab offset along the gradient by a distance modulated by the head's depth
    # data (the head's CT values, scaled).
    cat > "$W/slab.hf" <<'EOF'
slab(x[3], a[1]) { slab = min(x[2] + 236, min(122 - abs(x[1] + 122), 85 - abs(x[3] - 80))); }
EOF
    cat > "$W/relief.json" <<'EOF'
{"version": 1, "mappings": [{"kind": "offset-normal", "scale": 0.03,
  "distance": {"source": "d(x[3], a[1]) { array p[3]; p = [x[1], x[2] + 40, x[3]]; d = vmVolume(\"cranium_ct.nii.gz\", p, -1024, \"linear\", 0); }"}}]}
EOF
    "$VOLMORPH" --allow-external-data frep map "$W/slab.hf" --mapping "$W/relief.json" -o "$S/fig07_relief.png" \
        --bounds=-250,-250,-10,5,-150,170 --size 288 --view -60,15 >/dev/null
    fig savchenko_pasko "Fig. 7" "offsetting along the normal (Eq. 17, the gradient for the normal): a slab offset by a distance modulated by the CT head's data" \
        savchenko_pasko/fig07_relief.png
fi

# Figs. 8–9: function-dependent coordinate space mappings of the solid of Fig. 2.
"$VOLMORPH" frep map "$W/solid.hf" --mapping "$W/none.json" -o "$S/fig08b_section.png" --bounds=-1.1,-0.2,-1.1,1.1,1.1,1.1 "${P[@]}" --view -90,20 >/dev/null
cat > "$W/shell.json" <<'EOF'
{"version": 1, "mappings": [{"kind": "shell", "a": -12, "b": 0.6}]}
EOF
"$VOLMORPH" frep map "$W/solid.hf" --mapping "$W/shell.json" -o "$S/fig08c_shell_cut.png" --bounds=-1.1,-0.2,-1.1,1.1,1.1,1.1 "${P[@]}" --view -90,20 >/dev/null
fig savchenko_pasko "Fig. 8" "thin shell x₁ = x₂ = x₃ = a f(x') + b (Eq. 17, a = −12, b = 0.6) of the solid of Fig. 2: b the solid cut at y = −0.2 (through the drilled hole); c the shells (f ∈ [0, 0.06] and, where the diagonal crosses the drilled hole, a second inner one) with the front part removed" \
    savchenko_pasko/fig08b_section.png savchenko_pasko/fig08c_shell_cut.png
cat > "$W/maze.json" <<'EOF'
{"version": 1, "mappings": [{"kind": "maze", "a": 0.6, "b": 28, "c": 0}]}
EOF
"$VOLMORPH" frep map "$W/solid.hf" --mapping "$W/maze.json" -o "$S/fig09_maze.png" "${B[@]}" "${P[@]}" >/dev/null
fig savchenko_pasko "Fig. 9" "maze-like structure x₁ = x₂ = x₃ = a sin(b f(x') + c) (a = 0.6, b = 28) of the same solid: layers following its level sets, cut by the box" \
    savchenko_pasko/fig09_maze.png

# Figs. 10–11: a ball turned into a block with a hole by metamorphosis, by the coordinate
# mapping alone, and by both with the schedule of Fig. 11 (h₁ delayed, h₂ smooth).
cat > "$W/ball.hf" <<'EOF'
ball(x[3], a[1]) { array c[3]; c = [0, 0, 0]; ball = hfSphere(x, c, 0.8); }
EOF
cat > "$W/ring.hf" <<'EOF'
ring(x[3], a[1])
{
  array v[3]; array c[3];
  v = [-1.2, -0.35, -0.6]; c = [0, 0, 0];
  ring = hfBlock(x, v, 2.4, 0.7, 1.2) \ hfCylinderY(x, c, 0.35);
}
EOF
Q='[[0.8, 0, 0], [-0.8, 0, 0], [0, 0.8, 0], [0, -0.8, 0], [0, 0, 0.8], [0, 0, -0.8]]'
D='[[1.2, 0, 0], [-1.2, 0, 0], [0, 0.35, 0], [0, -0.35, 0], [0, 0, 0.6], [0, 0, -0.6]]'
cat > "$W/combined.json" <<EOF
{"version": 1, "mappings": [{"kind": "combined", "target": {"file": "ring.hf"},
  "sources": $Q, "targets": $D, "h1": "delayed:0.4", "h2": "smoothstep"}]}
EOF
cat > "$W/metamorphosis.json" <<'EOF'
{"version": 1, "mappings": [{"kind": "metamorphosis", "target": {"file": "ring.hf"}}]}
EOF
cat > "$W/coordinates.json" <<EOF
{"version": 1, "mappings": [{"kind": "handles", "sources": $Q, "targets": $D, "schedule": "smoothstep"}]}
EOF
F=(--frames 5 --size 144 --view 30,25 --bounds=-1.4,1.4)
rows=()
for kind in metamorphosis coordinates combined; do
    "$VOLMORPH" frep map "$W/ball.hf" --mapping "$W/$kind.json" "${F[@]}" -o "$W/$kind" >/dev/null
    for i in 0 1 2 3 4; do
        cp "$W/$kind/frame000$i.png" "$S/fig10_${kind}_$i.png"
        rows+=("savchenko_pasko/fig10_${kind}_$i.png")
    done
done
fig savchenko_pasko "Figs. 10–11" "transformation of a ball into a block with a hole, frames t = 0, ¼, ½, ¾, 1: a metamorphosis (Eq. 13); b coordinate space mapping of six control points; c combined mapping (Eq. 18) with the schedule h₁ = delayed:0.4, h₂ = smoothstep" \
    "${rows[@]}"

# Fig. 12: the ellipsoid moves between two walls while it turns into the block with a hole;
# its control points are displaced by a genetic search minimising the interpenetration with
# the walls' defining function.
cat > "$W/ellipsoid.hf" <<'EOF'
e(x[3], a[1]) { e = 1 - (x[1]/0.9)^2 - (x[2]/0.95)^2 - (x[3]/0.55)^2; }
EOF
cat > "$W/walls.hf" <<'EOF'
walls(x[3], a[1]) { walls = min(abs(x[2]) - 0.5, 0.45 - abs(x[1])); }
EOF
cat > "$W/motion.json" <<EOF
{"version": 1, "mappings": [{"kind": "collision-free-motion", "target": {"file": "ring.hf",
    "mappings": [{"kind": "affine", "matrix": [[0.7, 0, 0], [0, 1.0, 0], [0, 0, 0.7]]}]},
  "obstacles": {"file": "walls.hf"}, "path": [[-2.2, 0, 0], [2.2, 0, 0]],
  "control_points": $Q, "local_bounds": [[-1.2, -1.2, -1.2], [1.2, 1.2, 1.2]],
  "h1": "smoothstep", "search": {"keyframes": 9, "population": 16, "generations": 20, "seed": 1}}]}
EOF
"$VOLMORPH" frep map "$W/ellipsoid.hf" --mapping "$W/motion.json" --frames 5 --size 160 --view 20,55 \
    --bounds=-3,-1.2,-1.2,3,1.2,1.2 -o "$W/motion" | grep "collision-free motion" > "$S/fig12_motion.txt"
rows=()
for i in 0 1 2 3 4; do
    cp "$W/motion/frame000$i.png" "$S/fig12_motion_$i.png"
    rows+=("savchenko_pasko/fig12_motion_$i.png")
done
fig savchenko_pasko "Fig. 12" "combined mapping in 3D: an ellipsoid turns into a block with a hole while it moves through a gap between walls (|y| ≥ 0.5 for |x| ≤ 0.45); control-point displacements found by genetic search on the interpenetration (numbers in the text file)" \
    "${rows[@]}" savchenko_pasko/fig12_motion.txt

# §4.1.1: a solid through 300 scattered points on a peanut-like surface.
awk 'BEGIN { n = 300; for (i = 0; i < n; i++) { u = (i + 0.5) / n; th = atan2(sqrt(1 - (1 - 2*u)^2), 1 - 2*u);
    ph = 2.399963 * i; r = 0.6 + 0.25 * cos(2 * th);
    printf "%.6f %.6f %.6f\n", 1.6 * r * sin(th) * cos(ph), r * sin(th) * sin(ph), 1.3 * r * cos(th) } }' > "$W/peanut.xyz"
"$VOLMORPH" frep points "$W/peanut.xyz" -o "$W/peanut.ply" --grid 72 > "$S/points_peanut.txt"
"$VOLMORPH" mesh render "$W/peanut.ply" -o "$S/points_peanut.png" --size 288 --view 35,25 >/dev/null
fig savchenko_pasko "§4.1.1" "reconstruction from 300 scattered surface points: the points' moment ellipsoid plus a volume spline through them (largest |f| at a point in the text file)" \
    savchenko_pasko/points_peanut.png savchenko_pasko/points_peanut.txt

rm -rf "$W"
