#!/bin/sh
# Runs every test binary in $1/tests (cmocka), each under a time limit, and ends with the
# summary line "N passed, N failed" (CI parses it). Exit status 1 when anything failed.
# TEST_TIMEOUT: seconds per binary (default 600: under TSan the GL flight tests take minutes).
# A binary that runs past it is stopped (SIGTERM to its process group, which holds the daemons
# it started; SIGKILL 10 s later) and named in a "TIMEOUT: NAME (N s)" line; one that dies of a
# signal in a "CRASHED: NAME (signal N SIG)" line; each counts as one failed test when it
# printed no cmocka summary.
BUILD=${1:-build}
LIMIT=${TEST_TIMEOUT:-600}
case $LIMIT in '' | *[!0-9]* | 0)
	echo "tests/run.sh: TEST_TIMEOUT must be a positive number of seconds, not '$LIMIT'" >&2
	exit 2 ;;
esac
out=$(mktemp) || exit 1
trap 'rm -f "$out"' EXIT
trap 'exit 130' INT TERM
pass=0; fail=0; bad=""
for t in "$BUILD"/tests/test_*; do
	[ -x "$t" ] || continue
	name=$(basename "$t")
	start=$(date +%s)
	# A file, not $(...): a process the test leaves behind would hold the pipe open.
	timeout -k 10 "$LIMIT" "$t" > "$out" 2>&1 </dev/null; rc=$?
	took=$(($(date +%s) - start))
	grep -E '^\[ *(RUN|OK|FAILED|PASSED|SKIPPED|ERROR) *\]|^\[==========\]' "$out" \
		| grep -v '^\[ RUN' | grep -v '^\[       OK' || true
	p=$(sed -n 's/^\[  PASSED  \] \([0-9]*\) test.*/\1/p' "$out" | tail -n 1)
	f=$(sed -n 's/^\[  FAILED  \] \([0-9]*\) test.*/\1/p' "$out" | tail -n 1)
	pass=$((pass + ${p:-0})); fail=$((fail + ${f:-0}))
	[ $rc -eq 0 ] && continue
	[ -z "$f" ] && fail=$((fail + 1))
	bad="$bad $name"
	tail -n 30 "$out"
	# timeout(1): 124 after SIGTERM, 137 when SIGKILL had to follow (137 is also a test that
	# died of SIGKILL by itself: the elapsed time tells them apart).
	if [ $rc -eq 124 ] || { [ $rc -eq 137 ] && [ "$took" -ge "$LIMIT" ]; }; then
		echo "TIMEOUT: $name ($LIMIT s)"
	elif [ $rc -gt 128 ]; then
		sig=$((rc - 128))
		echo "CRASHED: $name (signal $sig $(kill -l $sig 2>/dev/null))"
	else
		echo "FAILED: $name (exit $rc)"
	fi
done
[ -n "$bad" ] && echo "failing test programs:$bad"
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ] && [ -z "$bad" ]
