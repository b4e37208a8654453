#!/bin/sh
# make data (also run by make deps): installs the Debian packages that carry the planet data
# and imports them with `clipmapctl import` into data/ (gitignored, never committed) — only
# files that are missing or older than their sources are rebuilt. As root it uses apt-get;
# otherwise it prints the exact command to run and fails.
#   data/earth/etopo5.tif     ETOPO5 heights (ferret-datasets, NetCDF, public domain, NOAA)
#   data/earth/bluemarble.tif NASA Blue Marble (flightgear-data-models: 8 tiles, gutters cut)
#   data/moon/moon.tif        Moon colour (stellarium-data moon_4k.jpg, USGS/Clementine)
#   data/mars/mars.tif        Mars colour (openuniverse-common mars.jpg)
#   data/earth/lines.gpkg     coastlines, national borders, rivers (GSHHG/WDBII in gmt-gshhg-low,
#                             dumped by gmt: scripts/earth_lines.sh; LGPL, public domain)
#   data/earth/water.tif      where water lies: 1 the ocean, 0.5 lakes, 0 land, on a 2′ grid: GSHHG's
#                             shorelines rasterised by gmt grdlandmask (earth.ini's sea_mask)
# proj-data brings the EGM96 geoid (/usr/share/proj/egm96_15.gtx).
set -eu
BUILD=${BUILD:-build}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
PKGS="ferret-datasets flightgear-data-models stellarium-data openuniverse-common proj-data
gmt gmt-gshhg-low gmt-dcw"
missing=""
for p in $PKGS; do
	st=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
	case "$st" in
	*"install ok installed"*) ;;
	*) missing="$missing $p" ;;
	esac
done
if [ -n "$missing" ]; then
	cmd="apt-get install -y --no-install-recommends$missing"
	if [ "$(id -u)" -ne 0 ]; then
		echo "make data: missing Debian packages:$missing" >&2
		echo "make data: run as root:  apt-get update && $cmd" >&2
		exit 1
	fi
	echo "make data: installing$missing"
	export DEBIAN_FRONTEND=noninteractive
	apt-get update -qq
	# shellcheck disable=SC2086
	apt-get install -y -qq --no-install-recommends $missing >/dev/null
fi

ETOPO=/usr/share/ferret-vis/data/etopo5.cdf
FG=/usr/share/games/flightgear/Models/Astro/Textures
MOON=/usr/share/stellarium/textures/moon_4k.jpg
MARS=/usr/share/openuniverse/textures/mars.jpg
GSHHG=/usr/share/gmt-gshhg
for f in "$ETOPO" "$MOON" "$MARS" "$FG/world_N1.png" "$FG/world_S4.png" "$GSHHG/binned_GSHHS_l.nc"; do
	[ -r "$f" ] || { echo "make data: $f is missing (its package is installed?)" >&2; exit 1; }
done

# Up to date when dst exists and no source is newer.
stale() {
	dst=$1; shift
	[ -f "$dst" ] || return 0
	for s in "$@"; do
		[ "$s" -nt "$dst" ] && return 0
	done
	return 1
}

now() { date +%s.%N; }
CTL="$BUILD/clipmapctl"
need=0
stale data/earth/etopo5.tif "$ETOPO" scripts/data.sh && need=1
stale data/earth/bluemarble.tif "$FG"/world_[NS][1-4].png && need=1
stale data/moon/moon.tif "$MOON" && need=1
stale data/mars/mars.tif "$MARS" && need=1
stale data/earth/lines.gpkg "$GSHHG"/binned_*_l.nc scripts/earth_lines.sh && need=1
stale data/earth/water.tif "$GSHHG"/binned_*_l.nc scripts/data.sh && need=1
[ $need -eq 0 ] && exit 0
${MAKE:-make} --no-print-directory -s "$CTL"
mkdir -p data/earth data/moon data/mars
t0=$(now)

imp() {
	dst=$1; shift
	ts=$(now)
	"$CTL" import "$@" -o "$dst" --quiet
	echo "make data: $dst ($(awk "BEGIN { printf \"%.1f\", $(now) - $ts }") s)"
}

if stale data/earth/etopo5.tif "$ETOPO" scripts/data.sh; then
	# NetCDF, variable ROSE, rows south→north, longitudes 0..360: import turns it north-up
	# and starts it at -180 (its bounds reach half a pixel past each pole). Two of its rows
	# near 81.2°S hold another place's heights over 40–67° of longitude (a trench ~2 km deep
	# across Queen Maud Land, a 1.7 km wall on the Filchner–Ronne ice shelf): the streak
	# repair (client/ctl/streaks.h) puts the mean of their neighbours there.
	imp data/earth/etopo5.tif "$ETOPO" --repair-rows 500
fi

if stale data/earth/bluemarble.tif "$FG"/world_[NS][1-4].png; then
	# Eight 2048² tiles, each a 90°×90° interior of 2016² inside a 16-pixel gutter:
	# N1..N4 west→east from -180° over 0..90°N, S1..S4 below. A GDAL VRT mosaics the
	# interiors into one 8064×4032 georeferenced raster without writing it out.
	vrt=data/earth/bluemarble.vrt
	{
		echo '<VRTDataset rasterXSize="8064" rasterYSize="4032">'
		echo '  <SRS>EPSG:4326</SRS>'
		echo '  <GeoTransform>-180, 0.044642857142857144, 0, 90, 0, -0.044642857142857144</GeoTransform>'
		for b in 1 2 3; do
			echo "  <VRTRasterBand dataType=\"Byte\" band=\"$b\">"
			for r in N S; do
				for c in 1 2 3 4; do
					x=$(( (c - 1) * 2016 ))
					y=0; [ $r = S ] && y=2016
					echo "    <SimpleSource><SourceFilename>$FG/world_$r$c.png</SourceFilename><SourceBand>$b</SourceBand>"
					echo "      <SrcRect xOff=\"16\" yOff=\"16\" xSize=\"2016\" ySize=\"2016\"/><DstRect xOff=\"$x\" yOff=\"$y\" xSize=\"2016\" ySize=\"2016\"/></SimpleSource>"
				done
			done
			echo '  </VRTRasterBand>'
		done
		echo '</VRTDataset>'
	} > "$vrt"
	imp data/earth/bluemarble.tif "$vrt"
	rm -f "$vrt"
fi

# Plain images without georeferencing: global, west edge at -180°.
stale data/moon/moon.tif "$MOON" && imp data/moon/moon.tif "$MOON"
stale data/mars/mars.tif "$MARS" && imp data/mars/mars.tif "$MARS"
if stale data/earth/lines.gpkg "$GSHHG"/binned_*_l.nc scripts/earth_lines.sh; then
	ts=$(now)
	sh scripts/earth_lines.sh data/earth/lines.gpkg
	echo "make data: data/earth/lines.gpkg ($(awk "BEGIN { printf \"%.1f\", $(now) - $ts }") s)"
fi
if stale data/earth/water.tif "$GSHHG"/binned_*_l.nc scripts/data.sh; then
	# 1 over the ocean, 0.5 over lakes and ponds, 0 over land and islands in lakes (-N: ocean,
	# land, lake, island, pond), pixel-registered on a 2′ grid (10800 × 5400; gmt writes
	# NetCDF).
	nc=$(mktemp -d)
	(cd "$nc" && gmt grdlandmask -Rd -I2m -Dl -N1/0/0.5/0/0.5 -r -Gwater.nc)
	imp data/earth/water.tif "$nc/water.nc"
	rm -rf "$nc"
fi
echo "make data: ready in $(awk "BEGIN { printf \"%.1f\", $(now) - $t0 }") s"
