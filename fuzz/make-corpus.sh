#!/usr/bin/env bash
# Writes the seed corpora of the fuzz targets from the project's own generators, example
# pipelines and a few hand-made cases. Run from anywhere; needs a built `lamina`.
set -euo pipefail
cd "$(dirname "$0")"
lamina="${LAMINA:-../target/release/lamina}"
[ -x "$lamina" ] || (cd .. && cargo build --release --quiet --bin lamina)
c=corpus
mkdir -p $c/stl $c/obj $c/threemf $c/threemf_components $c/pipeline $c/machine $c/script $c/pipeline_values $c/cli_roundtrip $c/plugin_messages
# The plugin boundary's messages: a sample of each direction, written by a unit test.
(cd .. && LAMINA_FUZZ_CORPUS="$PWD/fuzz/$c/plugin_messages" cargo test --quiet -p lamina-core --lib sample_messages_read_back >/dev/null)
for ext in stl obj 3mf; do
    dir=$ext; [ $ext = 3mf ] && dir=threemf
    "$lamina" generate tube --segments 12 --height 4 -o $c/$dir/tube.$ext -q
    "$lamina" generate gear --teeth 5 --arc_segments 1 --height 2 -o $c/$dir/gear.$ext -q
    "$lamina" generate cube -o $c/$dir/cube.$ext -q
done
"$lamina" generate gear-shaft --teeth 5 -o $c/threemf/assembly.3mf -q
# ASCII STL and a few odd cases by hand.
cat > $c/stl/ascii.stl <<'STL'
solid t
facet normal 0 0 1
outer loop
vertex 0 0 0
vertex 1 0 0
vertex 0 1 0
endloop
endfacet
facet normal 0 0 1
outer loop
vertex 0 0 0
vertex 0 1 0
vertex 0 0 1
endloop
endfacet
endsolid t
STL
printf 'solid lying\n' > $c/stl/empty-ascii.stl
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\no a\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\nvt 0 0\nf -1/1 -2/1 -3/1\n' > $c/obj/negative.obj
cp ../pipelines/*.toml $c/pipeline/
# The shipped machine profiles, and one that starts from a built-in profile.
cp ../machine/profiles/*.toml $c/machine/
printf 'base = "marlin-mixing-2in1"\nname = "mine"\n[bed]\nmax_height = 100.0\n' > $c/machine/based.toml
printf '[model]\nuse = "cube"\n[materials.a]\ncolour = [1, 2, 3]\n#set slice.thickness=0.5\n#set output=[{use = "json", path = "p.json"}]\n' > $c/pipeline/set.toml
cp ../pipelines/gradient.rhai $c/script/
printf 'sin(r * PI)' > $c/script/expression
printf '[r, 1.0 - r]' > $c/script/array
printf 'fn f(r, z) {\n  let a = [3, 1, 2];\n  a.sort();\n  clamp01(lerp(0.0, 1.0, r)) + 0.0 * z\n}\n' > $c/script/function.rhai
printf 'fn f(r) { if r > 0.5 { [1.0, 0.0] } else { #{ a: 1 }.a; [0.5, 0.5] } }\n' > $c/script/branch.rhai
# The structure-aware targets start from a few byte strings of each shape.
printf '\x00\x00\x00' > $c/pipeline_values/first
printf '\x02\x01\x05\x00\x06\x03' > $c/pipeline_values/wave
printf '\x04\x02\x09\x00\x02\x01' > $c/pipeline_values/skin
printf '\x00\x10\x05\x03\x01' > $c/cli_roundtrip/box
printf '\x02\x20\x01\x05\x00' > $c/cli_roundtrip/gear
du -sh $c
