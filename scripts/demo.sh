#!/bin/sh
# make demo: until the viewer and the real planets land (issues 4 and 5), the demo renders the
# procedural planet offline with clipmapctl and says where the pictures are.
set -eu
BUILD=${1:-build}
OUT=${DEMO_OUT:-out/demo}
mkdir -p "$OUT"
echo "clipmap demo: the streaming viewer is not yet available; rendering the procedural planet"
echo "offline with clipmapctl instead (2 cores: about a minute)."
"$BUILD/clipmapctl" render procedural color --level 3 --world --shade -o "$OUT/procedural-world.png"
"$BUILD/clipmapctl" render procedural height --level 3 --world -o "$OUT/procedural-height.png"
"$BUILD/clipmapctl" render procedural color --level 7 --at -9,-68 --tiles 3 --shade -o "$OUT/procedural-range.png"
"$BUILD/clipmapctl" graph procedural > "$OUT/procedural.dot"
echo "pictures in $OUT/: procedural-world.png (the whole planet, colour x hillshade),"
echo "procedural-height.png (16-bit heights), procedural-range.png (a mountain range, 3x3 tiles at level 7),"
echo "procedural.dot (the node graph)."
