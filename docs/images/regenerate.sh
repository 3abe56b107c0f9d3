#!/usr/bin/env bash
# Regenerates the README's pictures from the example pipelines with Lamina's own
# preview exporters (a picture output is appended to a copy of each pipeline).
# Run from the repository root: docs/images/regenerate.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release --quiet --bin lamina
lamina=target/release/lamina
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

picture() { # pipeline, picture name, output table
    local pipeline=$1 name=$2 table=$3
    cp "pipelines/$pipeline" "$tmp/$pipeline"
    cp pipelines/*.rhai "$tmp/" 2>/dev/null || true
    printf '\n[[output]]\n%b\n' "$table" >> "$tmp/$pipeline"
    "$lamina" run --quiet --out "$tmp/out-$name" "$tmp/$pipeline"
    find "$tmp/out-$name" -name '*.png' -exec cp {} "docs/images/$name.png" \;
    echo "docs/images/$name.png"
}

picture gear-z-gradient.toml gear-z-gradient 'use = "stack"\nsize = 360'
picture gear-z-wave.toml gear-z-wave 'use = "stack"\nsize = 360'
picture blade-zxy.toml blade-zxy 'use = "stack"\nsize = 360'
picture blade-idw.toml blade-idw 'use = "png"\nlayers = [40]\nsize = 480'
picture blade-skin.toml blade-skin 'use = "png"\nlayers = [40]\nsize = 480'
picture distance-field-power.toml distance-field-power 'use = "png"\nlayers = [1]\nsize = 360'
picture grading-sources.toml grading-sources 'use = "png"\nlayers = [2]\nsize = 360'
picture pipe-work-cycles.toml pipe-work-cycles 'use = "stack"\nsize = 360'
picture gear-mixing-gcode.toml gear-mixing-gcode 'use = "png"\nlayers = [10]\nsize = 480\ntoolpaths = false'
