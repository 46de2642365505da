#!/bin/bash
# Every integer setting of every integrator (`mcmc-render integrators`;
# max_depth and rr_depth once, with pt) set to VALUE (default 10^15) in a
# render of an 8×6 scene with --time 2, under a 4 GB address-space limit
# and a 30 s timeout. One line per setting: exit code (0 ran, 1 refused,
# 124 still running at 30 s although --time 2, 134 aborted), lines of
# stderr, its first two lines. Not run by CI (docs/fuzzing.md).
# Usage (from mcmc-render/): fuzz/probe_settings.sh BIN [VALUE]
bin=$(realpath "$1")
value=${2:-1000000000000000}
dir=$(mktemp -d)
cd "$dir" || exit 1
cat > scene.xml <<'XML'
<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="8"/><integer name="height" value="6"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="rectangle"><bsdf type="diffuse"/></shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.3"/><rotate x="1" angle="180"/><translate z="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>
</scene>
XML
"$bin" integrators |
  awk '/^[a-z]/{cur=$1} /^    [a-z_0-9]+ +integer/{print cur, $1}' |
  awk '!($2=="max_depth"||$2=="rr_depth") || $1=="pt"' |
  while read -r integ p; do
    out=$( (ulimit -v 4000000; timeout 30 nice -n 10 "$bin" render scene.xml --integrator "$integ" \
      --set "$p=$value" --time 2 --threads 1 --quiet --out o.exr) 2>&1 >/dev/null)
    rc=$?
    echo "$integ $p rc=$rc lines=$(printf '%s' "$out" | grep -c '') $(printf '%s' "$out" | head -2 | tr '\n' '|' | cut -c1-160)"
  done
rm -rf "$dir"
