#!/bin/sh
# Installs the Debian packages clipmap needs (idempotent), then the planet data
# (scripts/data.sh: its packages and the imports into data/). As root it uses apt-get;
# otherwise it prints the exact command to run and fails.
set -eu
PKGS="build-essential pkg-config libopenimageio-dev openimageio-tools libgeographiclib-dev
libcmocka-dev libxxhash-dev libzstd-dev liblmdb-dev liblz4-dev libsystemd-dev systemd clang libgdal-dev libtiff-dev
libegl-dev libegl-mesa0 libgl1-mesa-dri libgl-dev libosmesa6-dev glslang-tools libglfw3-dev xvfb xauth
scdoc graphviz"
missing=""
for p in $PKGS; do
	st=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
	case "$st" in
	*"install ok installed"*) ;;
	*) missing="$missing $p" ;;
	esac
done
if [ -z "$missing" ]; then
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
exec sh "$(dirname "$0")/data.sh"
