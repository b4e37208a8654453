#!/bin/sh
# make bench: every benchmark program, machine header first, then a summary that puts the key
# per-component figures beside the keep-up table (seed 003 Table 1). Figures, not pass/fail.
# bench_keepup also writes out/bench/keepup.json and out/bench/keepup.png.
BUILD=${1:-build}
LOG=$(mktemp -d /tmp/clipmap-bench.XXXXXX) || exit 1
trap 'rm -rf "$LOG"' EXIT
echo "== clipmap benchmarks ($(date -u '+%Y-%m-%d %H:%M UTC'), commit $(git rev-parse --short HEAD 2>/dev/null || echo '?'))"
"$BUILD/tests/bench_machine" | tee "$LOG/machine" || exit 1
for b in "$BUILD"/tests/bench_*; do
	[ -x "$b" ] || continue
	n=$(basename "$b")
	case "$n" in bench_machine) continue ;; esac
	echo "== $n"
	"$b" > "$LOG/$n" 2>&1
	rc=$?
	cat "$LOG/$n"
	[ $rc -eq 0 ] || { echo "$n failed"; exit 1; }
done
echo "== summary (one run)"
grep -h -e '^machine:' -e '^memcpy 64 MiB' "$LOG/machine"
[ -f "$LOG/bench_nodes" ] && grep -h '^node ' "$LOG/bench_nodes"
[ -f "$LOG/bench_noise_parent" ] && grep -h -e '^whole keys' "$LOG/bench_noise_parent"
[ -f "$LOG/bench_server" ] && grep -h -e 'round trip' -e 'cached tiles' -e 'ratios' -e 'server/note' "$LOG/bench_server"
[ -f "$LOG/bench_http" ] && grep -h -e '^http/cached' "$LOG/bench_http"
[ -f "$LOG/bench_sched" ] && grep -h -e '^sched/goal' "$LOG/bench_sched"
[ -f "$LOG/bench_view" ] && grep -h -e '^view/frame' -e '^view/flight' "$LOG/bench_view"
[ -f "$LOG/bench_keepup" ] && grep -h -v -e '^  keepup ' -e '^bench_keepup:' "$LOG/bench_keepup"
exit 0
