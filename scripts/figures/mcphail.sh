# shellcheck shell=bash
# McPhail's thesis, chapter 4: Fig. 4.2, one picture deformed by the same point handles with
# affine, similarity and rigid moving least squares and with the thin-plate spline. Sourced by
# scripts/seed_figures.sh (see its contract).
M="$OUT/mcphail"
mkdir -p "$M"
"$VOLMORPH" phantom clay-block --size 128 -o "$M/clay.nii.gz"
"$VOLMORPH" slice "$M/clay.nii.gz" -o "$M/fig4_2_input.png" --axis z --index 64 >/dev/null
cat > "$M/fig4_2_handles.json" <<'JSON'
{"points": [
  {"source": [20, 20], "target": [20, 20]},
  {"source": [107, 20], "target": [100, 34]},
  {"source": [64, 64], "target": [76, 56]},
  {"source": [20, 107], "target": [30, 100]},
  {"source": [107, 107], "target": [107, 107]},
  {"source": [64, 20], "target": [64, 26]}
]}
JSON
files=(mcphail/fig4_2_input.png)
for method in affine similarity rigid tps; do
    "$VOLMORPH" mls2d "$M/fig4_2_input.png" --handles "$M/fig4_2_handles.json" \
        -o "$M/fig4_2_$method.png" --method "$method" >/dev/null
    files+=("mcphail/fig4_2_$method.png")
done
fig mcphail "Fig. 4.2" "a slice of the clay block and the same six point handles applied by affine, similarity and rigid MLS and by the thin-plate spline (r² log r), left to right" \
    "${files[@]}" mcphail/fig4_2_handles.json
rm -f "$M/clay.nii.gz"
