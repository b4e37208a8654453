#!/bin/sh
# The wings' include rule (docs/ARCHITECTURE.md), checked by `make check`: each file may include
# only the wings its own wing may use, named by their path ("common/grid.h", "engine/sched.h",
# "client/net.h"); a bare "x.h" must sit in the including file's own directory. The engine has
# no sockets, no protocol and no logging. Prints each offending line; exit 1 when any.
cd "$(dirname "$0")/.." || exit 1
bad=0
check() { # wing, allowed include prefixes (regex), files...
	wing=$1; allow=$2; shift 2
	for f in "$@"; do
		[ -f "$f" ] || continue
		dir=$(dirname "$f")
		grep -n '^[[:space:]]*#[[:space:]]*include[[:space:]]*"' "$f" | while IFS= read -r line; do
			inc=$(printf '%s\n' "$line" | sed 's/.*include[[:space:]]*"\([^"]*\)".*/\1/')
			case "$inc" in
			*/*) printf '%s\n' "$inc" | grep -Eq "^($allow)" && continue ;;
			*) { [ -f "$dir/$inc" ] || { [ "$wing" = view ] && case "$inc" in *_vert.h|*_frag.h) true ;; *) false ;; esac; }; } && continue ;;
			esac
			echo "$f:${line%%:*}: the $wing wing may not include \"$inc\""
		done
	done
}
out=$(
	check common 'common/' common/*.c common/*.h common/*.cpp
	check engine 'common/(grid|seagrid|ini|img|geo|normalmap|xalloc|xthread|errbuf|clock|pixfmt|tilecodec)\.h|engine/' \
		daemon/engine/*.[ch] daemon/engine/nodes/*.[ch]
	check server 'common/|engine/' daemon/*.[ch]
	check client 'common/' client/*.[ch]
	check ctl 'common/|engine/|client/[a-z_]+\.h' client/ctl/*.[ch]
	check view 'common/|engine/|client/[a-z_]+\.h' client/view/*.[ch]
	grep -n -E '#include <(sys/socket|sys/epoll|netinet/|arpa/)' daemon/engine/*.[ch] daemon/engine/nodes/*.[ch] |
		sed 's/$/  (the engine has no sockets)/'
)
if [ -n "$out" ]; then
	printf '%s\n' "$out"
	echo "layers: include rule broken (docs/ARCHITECTURE.md)"
	exit 1
fi
echo "layers: every include follows the wings' rule"
