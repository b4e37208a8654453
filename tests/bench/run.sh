#!/bin/sh
# make bench: every benchmark program, machine header first. Figures, not pass/fail.
BUILD=${1:-build}
echo "== clipmap benchmarks ($(date -u '+%Y-%m-%d %H:%M UTC'), commit $(git rev-parse --short HEAD 2>/dev/null || echo '?'))"
"$BUILD/tests/bench_machine" || exit 1
for b in "$BUILD"/tests/bench_*; do
	[ -x "$b" ] || continue
	case "$b" in */bench_machine) continue ;; esac
	echo "== $(basename "$b")"
	"$b" || { echo "$(basename "$b") failed"; exit 1; }
done
