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
"$BUILD/clipmapctl" render procedural color 12 11 1372 612 --shade -o "$OUT/procedural-tile.png"
"$BUILD/clipmapctl" graph procedural > "$OUT/procedural.dot"
echo "pictures in $OUT/: procedural-world.png (the whole planet, colour x hillshade),"
echo "procedural-height.png (16-bit heights), procedural-tile.png (one tile at level 11),"
echo "procedural.dot (the node graph)."
