# shellcheck shell=bash
# True & Hughes 1992, "Volume warping": Figs. 8–14 and the §5.1/§8 sizes (ISIZE 30,
# TSIZE 38, CSIZE 9). Sourced by scripts/seed_figures.sh (see its contract).
T="$OUT/true1992"
mkdir -p "$T"
R=(--mode iso --level 127 --view 35,25 --size 320x320)

# Fig. 8: the uniform cubic lattice (CSIZE = 9) placed on the voxel box of a 30³ model.
"$VOLMORPH" phantom teapot --size 30 -o "$T/teapot30.nii.gz"
"$VOLMORPH" lattice init "$T/teapot30.nii.gz" --counts 9,9,9 -o "$T/fig08_lattice.json" >/dev/null
fig true1992 "Fig. 8" "identity 9×9×9 uniform cubic B-spline lattice on the voxel box of a 30³ teapot (CSIZE 9)" \
    true1992/fig08_lattice.json

# Figs. 9–10: the teapot, and the spout lowered by one drag (magnet tool of radius 0.75).
"$VOLMORPH" phantom teapot --size 64 -o "$T/teapot.nii.gz"
"$VOLMORPH" render "$T/teapot.nii.gz" "${R[@]}" -o "$T/fig09_teapot.png" >/dev/null
fig true1992 "Fig. 9" "teapot, original sculpture (64³ density, isosurface 127)" true1992/fig09_teapot.png
"$VOLMORPH" drag "$T/teapot.nii.gz" --from 0.76,0,0.25 --to 0.86,0,-0.02 --tool sphere:0.75 \
    -o "$T/fig10_spout.nii.gz" --lattice-out "$T/fig10_lattice.json" >/dev/null
"$VOLMORPH" render "$T/fig10_spout.nii.gz" "${R[@]}" -o "$T/fig10_spout.png" >/dev/null
fig true1992 "Fig. 10" "teapot warped to adjust the spout position (one drag, antialiased push-forward)" \
    true1992/fig10_spout.png

# Figs. 11–12: the clay block, a corner pushed in with a box tool limited to a realm, and
# pulled out past the source grid onto a padded target grid (§5.1: ISIZE 30 → TSIZE 38).
"$VOLMORPH" phantom clay-block --size 30 -o "$T/clay30.nii.gz"
"$VOLMORPH" render "$T/clay30.nii.gz" "${R[@]}" -o "$T/clay30.png" >/dev/null
"$VOLMORPH" drag "$T/clay30.nii.gz" --from 0.62,0.38,0.33 --to 0.42,0.2,0.15 \
    --tool box:0.6,0.6,0.6 --realm region:0,0,0,1.2,1.2,1.2 -o "$T/fig11_inward.nii.gz" >/dev/null
"$VOLMORPH" render "$T/fig11_inward.nii.gz" "${R[@]}" -o "$T/fig11_inward.png" >/dev/null
fig true1992 "Fig. 11" "clay block (30³), corner warped inward: box tool, realm = the +x+y+z octant" \
    true1992/clay30.png true1992/fig11_inward.png
"$VOLMORPH" lattice init --corner -1.5,-1.5,-1.5 --edge 3,0,0 --edge 0,3,0 --edge 0,0,3 \
    --counts 9,9,9 -o "$T/big_lattice.json" >/dev/null
"$VOLMORPH" drag "$T/clay30.nii.gz" --lattice "$T/big_lattice.json" --from 0.62,0.38,0.33 \
    --to 0.98,0.74,0.69 --tool sphere:1.3 --pad 4 -o "$T/fig12_outward.nii.gz" >/dev/null
"$VOLMORPH" render "$T/fig12_outward.nii.gz" "${R[@]}" -o "$T/fig12_outward.png" >/dev/null
"$VOLMORPH" info "$T/fig12_outward.nii.gz" | grep -v '^file:' > "$T/fig12_outward_info.txt"
fig true1992 "Fig. 12 / §5.1" "clay block, corner warped outward beyond the 30³ source grid onto a padded 38³ target grid (ISIZE 30, TSIZE 38): nothing clipped" \
    true1992/fig12_outward.png true1992/fig12_outward_info.txt

# Figs. 13–14: the tree, and the tree bent as if by a strong gust: a start/goal curve drag
# (§6.3) of 8 constrained drags on a lattice larger than the grid, written onto a padded grid.
"$VOLMORPH" phantom tree --size 64 -o "$T/tree.nii.gz"
"$VOLMORPH" render "$T/tree.nii.gz" "${R[@]}" -o "$T/fig13_tree.png" >/dev/null
fig true1992 "Fig. 13" "tree, original sculpture (phantom tree, 64³)" true1992/fig13_tree.png
"$VOLMORPH" drag "$T/tree.nii.gz" --lattice "$T/big_lattice.json" \
    --start-curve "0,0,-0.45;0,0,-0.1;0.4,0,0.25;-0.2,0.35,0.25;-0.2,-0.35,0.25" \
    --goal-curve "0.03,0,-0.45;0.2,0,-0.12;0.75,0,0.12;0.15,0.35,0.15;0.15,-0.35,0.15" \
    --steps 8 --frames "$T/fig14_frames" --tool sphere:1.2 --pad 0,0,0,12,0,0 \
    -o "$T/fig14_gust.nii.gz" >/dev/null
"$VOLMORPH" render "$T/fig14_gust.nii.gz" "${R[@]}" -o "$T/fig14_gust.png" >/dev/null
rm -rf "$T/fig14_frames"
fig true1992 "Fig. 14" "tree warped as if caught in a strong gust of wind: start/goal curve drag in 8 steps onto a grid padded 12 voxels towards +x" \
    true1992/fig14_gust.png

# Volumes are intermediate: keep the pictures and small text files only.
rm -f "$T"/*.nii.gz "$T/big_lattice.json" "$T/fig10_lattice.json"
