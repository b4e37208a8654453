#!/bin/sh
# scripts/contact-sheet.sh PLANET [OUT.png]: one row of pictures of conf/planets/PLANET.ini,
# rendered in-process by build/clipmapview (every level complete) and put side by side with
# oiiotool, each cell labelled. Cells, left to right:
#   orbit (straight down), 80 km, 10 km, 1 km, 100 m, 10 m, 2 m (looking down at an angle, the
#   planet's showpiece in the middle of the picture: the Himalaya, the crater Tycho, Valles
#   Marineris, a range of the procedural planet), north pole and south pole from 150 km
#   (looking at the pole at 35° down). Every cell is lit from its upper left.
# The labels need a TrueType font (fc-match; DejaVu); without one the cells are unlabelled, in
# the order above. OUT defaults to docs/img/contact-PLANET.png. 2 cores: about half a minute.
#   CONTACT_CELL (320x180: the size of a cell; each is rendered at twice that and shrunk),
#   CONTACT_BUILD (build), CONTACT_PLANETS (conf/planets: where PLANET.ini is)
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
if [ $# -lt 1 ] || [ $# -gt 2 ]; then
	echo "usage: $0 PLANET [OUT.png]" >&2
	exit 2
fi
PLANET=$1
OUT=${2:-$ROOT/docs/img/contact-$PLANET.png}
CELL=${CONTACT_CELL:-320x180}
BUILD=${CONTACT_BUILD:-$ROOT/build}
INI=${CONTACT_PLANETS:-$ROOT/conf/planets}/$PLANET.ini
VIEW=$BUILD/clipmapview
[ -f "$INI" ] || { echo "$0: $INI: no such planet file" >&2; exit 2; }
[ -x "$VIEW" ] || { echo "$0: $VIEW is missing (make -j2)" >&2; exit 1; }
command -v oiiotool >/dev/null ||
	{ echo "$0: oiiotool is missing (openimageio-tools)" >&2; exit 1; }
W=${CELL%x*}
H=${CELL#*x}
case "$W$H" in *[!0-9]*|"") echo "$0: CONTACT_CELL=$CELL: want WxH" >&2; exit 2 ;; esac

# The showpiece: LAT LON HEADING — the point each low view looks at (along HEADING) — the
# orbit altitude (1.4 radii: the disc fills most of the height), the radius (metres) and the
# density of the air (--haze: none on the Moon and Mars, whose air the viewer does not model).
case "$PLANET" in
# Everest from the south; Tycho from the north; Valles Marineris (in the colour map: the
# heights are synthetic); the range of the procedural planet's western continent.
earth)      SPOT="27.99 86.93 0";   ORBIT=9000000; R=6371000; HAZE=1 ;;
moon)       SPOT="-43.3 -11.2 180"; ORBIT=2450000; R=1737400; HAZE=0 ;;
mars)       SPOT="-9.0 -68.0 90";   ORBIT=4800000; R=3389500; HAZE=0 ;;
procedural) SPOT="-2.5 -60.5 30";   ORBIT=9000000; R=6371000; HAZE=1 ;;
*)          SPOT="30 0 0";          ORBIT=9000000; R=6371000; HAZE=1 ;;
esac
# shellcheck disable=SC2086 # split on purpose: three numbers
set -- $SPOT
LAT=$1 LON=$2 HDG=$3

# back LAT LON ALT HEADING PITCH: the camera that, ALT above the ground and pitched PITCH (< 0),
# looks at LAT,LON along HEADING — stepped back ALT / tan(−PITCH) over a sphere of radius R.
back() {
	awk -v lat="$1" -v lon="$2" -v alt="$3" -v h="$4" -v p="$5" -v r="$R" 'BEGIN {
		d2r = atan2(1, 1) / 45
		d = alt * cos(-p * d2r) / sin(-p * d2r) / r / d2r
		la = lat - d * cos(h * d2r)
		c = cos(lat * d2r)
		lo = (c > 1e-6) ? lon - d * sin(h * d2r) / c : lon
		if (la > 90) la = 180 - la
		if (la < -90) la = -180 - la
		if (lo < -180) lo += 360
		if (lo > 180) lo -= 360
		printf "%.6f,%.6f,%s,%s,%s", la, lo, alt, h, p
	}'
}

FONT=""
if command -v fc-match >/dev/null; then
	FONT=$(fc-match -f '%{file}' 'DejaVu Sans:bold' 2>/dev/null || true)
fi
[ -n "$FONT" ] && [ -f "$FONT" ] || FONT=""

TMP=$(mktemp -d "${TMPDIR:-/tmp}/contact.XXXXXX")
trap 'rm -rf "$TMP"' EXIT INT TERM
t0=$(date +%s)
n=0
# cell LABEL LAT,LON,ALT,HEADING,PITCH: lit from the picture's upper left (the sun's azimuth
# 315° from the camera's heading, 35° up), as a map's hill shading is: lit from below, a
# crater reads as a dome (issue 11)
cell() {
	n=$((n + 1))
	f="$TMP/$n.png"
	hdg=$(echo "$2" | cut -d, -f4)
	sun=$(awk -v h="$hdg" 'BEGIN { a = h + 315; while (a >= 360) a -= 360; printf "%g,35", a }')
	if ! "$VIEW" --planet "$INI" --camera "$2" --sun "$sun" --haze "$HAZE" \
		--size "$((W * 2))x$((H * 2))" \
		--wait-complete --timeout 120 -o "$TMP/big.png" >"$TMP/log" 2>&1; then
		echo "$0: $PLANET $1: clipmapview failed:" >&2
		cat "$TMP/log" >&2
		exit 1
	fi
	if [ -n "$FONT" ]; then
		oiiotool "$TMP/big.png" --resize "${W}x${H}" \
			--text:x=6:y=$((H / 12 + 6)):size=$((H / 12 + 2)):color=1,1,1:shadow=1:font="$FONT" \
			"$1" -o "$f"
	else
		oiiotool "$TMP/big.png" --resize "${W}x${H}" -o "$f"
	fi
	CELLS="$CELLS $f"
}
CELLS=""
cell "$PLANET: orbit" "$LAT,$LON,$ORBIT,0,-90"
cell "80 km" "$(back "$LAT" "$LON" 80000 "$HDG" -40)"
cell "10 km" "$(back "$LAT" "$LON" 10000 "$HDG" -30)"
cell "1 km" "$(back "$LAT" "$LON" 1000 "$HDG" -25)"
cell "100 m" "$(back "$LAT" "$LON" 100 "$HDG" -20)"
cell "10 m" "$(back "$LAT" "$LON" 10 "$HDG" -15)"
cell "2 m" "$(back "$LAT" "$LON" 2 "$HDG" -12)"
cell "north pole, 150 km" "$(back 90 "$LON" 150000 0 -35)"
cell "south pole, 150 km" "$(back -90 "$LON" 150000 180 -35)"

mkdir -p "$(dirname "$OUT")"
# shellcheck disable=SC2086 # CELLS holds mktemp paths without spaces
oiiotool $CELLS --mosaic:pad=2 "${n}x1" -d uint8 -o "$OUT"
echo "$OUT: $PLANET, $n cells of $CELL in $(( $(date +%s) - t0 )) s"
