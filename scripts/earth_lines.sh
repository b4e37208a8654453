#!/bin/sh
# earth_lines.sh OUT.gpkg — the Earth's coastlines, national borders and rivers for the
# `vector` node (conf/planets/earth.ini), dumped from GSHHG/WDBII (Debian: gmt, gmt-gshhg-low)
# with GMT's own tool (`gmt coast -M`: multi-segment text, one segment per bin piece) and
# written through ogr2ogr into a GeoPackage: layer "lines", EPSG:4326, fields
#   kind   coast | border | river
#   level  GSHHG's level (coast: 1 land/ocean), WDBII's (border: 1 national; river: 1 major
#          permanent rivers, 2 more major rivers, 3 other permanent rivers)
# Resolution "low" (-Dl): about 1 km detail, 25 000 segments.
set -eu
case $1 in /*) out=$1 ;; *) out=$(pwd)/$1 ;; esac
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cd "$tmp" # gmt writes gmt.history and gmt.conf into the working directory
# GMT's multi-segment text ("> … Level N" headers, then "lon<TAB>lat" lines) to GeoJSON.
tojson() { # kind
	awk -v kind="$1" '
	function flush() {
		if (n >= 2) {
			printf "%s{\"type\":\"Feature\",\"properties\":{\"kind\":\"%s\",\"level\":%d},", sep, kind, lev
			printf "\"geometry\":{\"type\":\"LineString\",\"coordinates\":[%s]}}\n", pts
			sep = ","
		}
		n = 0; pts = ""
	}
	BEGIN { sep = ""; n = 0 }
	/^>/ { flush(); lev = $NF + 0; next }
	NF >= 2 { pts = pts (n ? "," : "") "[" $1 "," $2 "]"; n++ }
	END { flush() }'
}
{
	echo '{"type":"FeatureCollection","features":['
	gmt coast -Rd -Dl -A0/0/1 -W -M | tojson coast
	echo ','
	gmt coast -Rd -Dl -N1 -M | tojson border
	echo ','
	gmt coast -Rd -Dl -I1 -I2 -I3 -M | tojson river
	echo ']}'
} > "$tmp/lines.geojson"
rm -f "$out.tmp.gpkg"
ogr2ogr -q -f GPKG -nln lines -a_srs EPSG:4326 "$out.tmp.gpkg" "$tmp/lines.geojson"
mv "$out.tmp.gpkg" "$out"
