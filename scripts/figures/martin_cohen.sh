# shellcheck shell=bash
# Martin & Cohen, "Representation and Extraction of Volumetric Attributes Using Trivariate
# Splines": Fig. 1 / §3 (the modelling operators: a GRIN lens from an aggregate curve, revolved
# and extruded), §5.1 / Fig. 3 (planar slice and isosurface by Bézier subdivision), §5.2 (volume
# rendering), §5.4 (several volumes in one picture) and §5.3 / Fig. 5 (optical paths through
# the graded index, with the three path methods' back focal distances). Sourced by
# scripts/seed_figures.sh (see its contract).
C="$OUT/martin_cohen"
mkdir -p "$C"

# Fig. 1 / §3: the recipe (curve → attach eta → revolve → extrude) and the model it builds,
# cut by the plane z = 0.5 and coloured by the index: it varies only radially.
"$VOLMORPH" nurbs example grin-lens-recipe -o "$C/fig1_lens_recipe.json" >/dev/null
"$VOLMORPH" nurbs model "$C/fig1_lens_recipe.json" -o "$C/lens.json" >/dev/null
"$VOLMORPH" nurbs slice "$C/lens.json" --plane 0,0,1,-0.5 --attribute eta --colormap viridis \
    -o "$C/lens_cut.ply" >/dev/null
"$VOLMORPH" mesh render "$C/lens_cut.ply" --view 0,90 --up z --size 320x320 \
    -o "$C/fig1_lens_slice.png" >/dev/null
fig martin-cohen "Fig. 1 / §3" "GRIN lens modelled by the §3 operators from a recipe (profile line + index curve n₀(1 − A r²/2) → revolve 360° → extrude), cut at z = 0.5 and coloured by the index (viridis): the attribute carried by the revolution varies only radially" \
    martin_cohen/fig1_lens_recipe.json martin_cohen/fig1_lens_slice.png

# §5.1 / Fig. 3: a sampled volume (the teapot, 40³) fitted as an attribute (16³ tricubic
# least squares), its isosurface and a planar cut, both by root isolation with Bézier
# subdivision and refinement to a flatness tolerance.
"$VOLMORPH" phantom teapot --size 40 -o "$C/teapot.nii.gz" >/dev/null
"$VOLMORPH" nurbs fit "$C/teapot.nii.gz" --control-points 16 --name density -o "$C/teapot.json" >/dev/null
"$VOLMORPH" nurbs isosurface "$C/teapot.json" --attribute density --level 127 \
    --color-by density -o "$C/teapot_iso.ply" >/dev/null
"$VOLMORPH" mesh render "$C/teapot_iso.ply" --view 35,25 --up z --size 320x320 --no-colors \
    -o "$C/fig3_isosurface.png" >/dev/null
"$VOLMORPH" nurbs slice "$C/teapot.json" --plane 0,1,0,0 --attribute density --colormap hot \
    -o "$C/teapot_cut.ply" >/dev/null
"$VOLMORPH" mesh render "$C/teapot_cut.ply" --view 90,0 --up z --size 320x320 \
    -o "$C/fig3_planar_cut.png" >/dev/null
fig martin-cohen "§5.1 / Fig. 3" "isosurface density = 127 and the planar cut y = 0 (coloured by density) of the teapot fitted as a 16³ tricubic attribute, both found by Bézier subdivision of the zero set" \
    martin_cohen/fig3_isosurface.png martin_cohen/fig3_planar_cut.png

# §5.2: volume rendering by ray tracing the spline (boundary hits, Newton tracking, front to
# back compositing) of the lens's index and of the fitted teapot.
"$VOLMORPH" nurbs render "$C/lens.json" --attribute eta --transfer '1.1:0,0,0.3,0;1.5:1,0.8,0.2,0.9' \
    --view 35,30 --size 256x256 -o "$C/render_lens.png" >/dev/null
"$VOLMORPH" nurbs render "$C/teapot.json" --attribute density \
    --transfer '0:0,0,0,0;100:0,0,0,0;140:0.9,0.5,0.2,0.9;255:1,1,0.9,1' --shade \
    --view 35,25 --size 256x256 -o "$C/render_teapot.png" >/dev/null
fig martin-cohen "§5.2" "volume rendering of the lens's index (transfer: blue → yellow as η rises) and of the teapot's fitted density (shaded)" \
    martin_cohen/render_lens.png martin_cohen/render_teapot.png

# §5.4: several volumes in one picture. The lens modelled again with its axis at x = 1.4,
# z from −0.5 to 0.5, in front of the teapot's spout side as seen from +x; every ray passes
# through both volumes and their samples are composited by depth.
cat > "$C/lens_moved_recipe.json" <<'JSON'
{
  "format": "volmorph-nurbs-recipe",
  "version": 1,
  "steps": [
    { "curve":   { "name": "profile", "degree": 1, "points": [[1.4, 0, -0.5], [2.4, 0, -0.5]] } },
    { "attach":  { "name": "graded", "to": "profile", "attribute": "eta",
                   "spline": { "degree": 2, "values": [1.5, 1.5, 1.125] } } },
    { "revolve": { "name": "disk", "of": "graded", "axis_point": [1.4, 0, -0.5],
                   "axis_direction": [0, 0, 1], "angle_degrees": 360 } },
    { "extrude": { "name": "lens", "of": "disk", "direction": [0, 0, 1] } }
  ],
  "result": "lens"
}
JSON
"$VOLMORPH" nurbs model "$C/lens_moved_recipe.json" -o "$C/lens_moved.json" >/dev/null
for view in 15 90; do
    "$VOLMORPH" nurbs render "$C/teapot.json" --add "$C/lens_moved.json" \
        --attribute density --attribute eta \
        --transfer '0:0,0,0,0;100:0,0,0,0;140:0.9,0.5,0.2,0.9;255:1,1,0.9,1' \
        --transfer '1.1:0,0.2,0.6,0.3;1.5:0.3,0.8,1,0.9' \
        --view "$view,20" --size 300x250 -o "$C/scene_two_volumes_$view.png" >/dev/null
done
fig martin-cohen "§5.4" "two volumes in one picture (the §5.4 TraceRay loop), each with its own attribute and transfer function: the fitted teapot (density, orange-white) and a second GRIN lens (index, translucent blue) modelled at x = 1.4; from azimuth 15° the lens is in front and the teapot is seen through it, from 90° they stand side by side" \
    martin_cohen/scene_two_volumes_15.png martin_cohen/scene_two_volumes_90.png martin_cohen/lens_moved_recipe.json

# §5.3 / Fig. 5: rays through the graded index, and the back focal distance by each method
# against the exact trace (the meridional ray ODE) and the paraxial formula.
"$VOLMORPH" nurbs trace-optics --example grin-lens --rays 11 --size 640x400 \
    -o "$C/fig5_grin_rays.png" | sed "s|$C/||" > "$C/fig5_focus.txt"
for m in ray-equation snell; do
    "$VOLMORPH" nurbs trace-optics --example grin-lens --rays 1 --method "$m" --size 64x40 \
        -o "$C/tmp.png" | grep -E '^(traced|measured)' | sed "s|$C/||" >> "$C/fig5_focus.txt"
done
"$VOLMORPH" nurbs trace-optics --example grin-lens --rays 1 --method ray-equation --step 0.001 \
    --size 64x40 -o "$C/tmp.png" | grep -E '^(traced|measured)' | sed "s|$C/||" >> "$C/fig5_focus.txt"
fig martin-cohen "§5.3 / Fig. 5" "11 parallel rays bent by the GRIN lens (n = 1.5(1 − 0.25 r²)) and meeting near the focus; the text lists the probe ray's back focal distance by rk45 (default), the ray-equation form (default step and 0.001) and the paper's literal Snell stepping, against the exact trace and the paraxial value" \
    martin_cohen/fig5_grin_rays.png martin_cohen/fig5_focus.txt

# Keep the pictures, recipes and small text files only.
rm -f "$C"/*.ply "$C"/*.nii.gz "$C/tmp.png" "$C/lens.json" "$C/lens_moved.json" "$C/teapot.json"
