# Sourced by bench scripts: MeshLab's Hausdorff filter (meshlabserver under xvfb-run), the
# independent reference for distances to the input. Needs $work (a scratch folder) and $samples.
# hausdorff_oneway A B prints "mean max" of the distance from samples of A to the surface of B,
# in object units (the first "min : ..." line of MeshLab's log; the second is relative to the
# bounding-box diagonal).
cat > "$work/hausdorff.mlx" <<EOF
<!DOCTYPE FilterScript>
<FilterScript>
 <filter name="Hausdorff Distance">
  <Param type="RichMesh" value="0" name="SampledMesh"/>
  <Param type="RichMesh" value="1" name="TargetMesh"/>
  <Param type="RichBool" value="false" name="SaveSample"/>
  <Param type="RichBool" value="true" name="SampleVert"/>
  <Param type="RichBool" value="true" name="SampleEdge"/>
  <Param type="RichBool" value="false" name="SampleFauxEdge"/>
  <Param type="RichBool" value="true" name="SampleFace"/>
  <Param type="RichInt" value="$samples" name="SampleNum"/>
  <Param type="RichAbsPerc" value="10" min="0" max="10" name="MaxDist"/>
 </filter>
</FilterScript>
EOF
hausdorff_oneway() {
  local log="$work/hd.$RANDOM.log"
  xvfb-run -a meshlabserver -i "$1" -i "$2" -s "$work/hausdorff.mlx" -l "$log" >"$work/hd.out" 2>&1 ||
    { tail -5 "$work/hd.out" >&2; echo "meshlabserver failed on $1 vs $2" >&2; exit 1; }
  awk '/min :/ { for (i = 1; i <= NF; i++) { if ($i == "max") mx = $(i + 1); if ($i == "mean") mn = $(i + 2) }; print mn, mx; exit }' "$log"
}
