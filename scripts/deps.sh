#!/bin/sh
# Installs the Debian packages clipmap needs (idempotent), then the planet data
# (scripts/data.sh: its packages and the imports into data/). As root it uses apt-get;
# otherwise it prints the exact command to run and fails.
set -eu
PKGS="build-essential pkg-config libopenimageio-dev openimageio-tools libgeographiclib-dev
libcmocka-dev libxxhash-dev libzstd-dev liblmdb-dev liblz4-dev libwebp-dev libsystemd-dev systemd clang libgdal-dev libtiff-dev
libegl-dev libegl-mesa0 libgl1-mesa-dri libgl-dev libosmesa6-dev glslang-tools libglfw3-dev xvfb xauth
scdoc graphviz libmicrohttpd-dev zlib1g-dev gdal-bin curl prometheus chromium wrk
redis-server libhiredis-dev haproxy libgnutls28-dev gnutls-bin iproute2"
missing=""
for p in $PKGS; do
	st=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
	case "$st" in
	*"install ok installed"*) ;;
	*) missing="$missing $p" ;;
	esac
done
# CesiumJS for the browser page and the tests of the Cesium terrain (npm registry), into
# build/npm; a machine without npm or network gets a warning and those tests skip.
npm_deps() {
	dir="$(dirname "$0")/../build/npm"
	[ -f "$dir/node_modules/cesium/package.json" ] && return 0
	# Debian's nodejs and npm when there is no npm at all (a NodeSource or other install
	# is left alone: Debian's npm would conflict with it).
	if ! command -v npm >/dev/null && [ "$(id -u)" -eq 0 ]; then
		DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
			nodejs npm >/dev/null 2>&1 || true
	fi
	if ! command -v npm >/dev/null; then
		echo "make deps: npm not found: the Cesium tests will skip" >&2
		return 0
	fi
	mkdir -p "$dir"
	npm install --silent --no-audit --no-fund --prefix "$dir" cesium@1.145.0 >/dev/null 2>&1 ||
		echo "make deps: npm install cesium failed: the Cesium tests will skip" >&2
}
if [ -z "$missing" ]; then
	npm_deps
	exec sh "$(dirname "$0")/data.sh"
fi
cmd="apt-get install -y --no-install-recommends$missing"
if [ "$(id -u)" -ne 0 ]; then
	echo "make deps: missing Debian packages:$missing" >&2
	echo "make deps: run as root:  apt-get update && $cmd" >&2
	exit 1
fi
echo "make deps: installing$missing"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
# shellcheck disable=SC2086
apt-get install -y -qq --no-install-recommends $missing >/dev/null
npm_deps
exec sh "$(dirname "$0")/data.sh"
