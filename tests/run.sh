#!/bin/sh
# Runs every unit test binary in $1/tests (cmocka), each under a time limit, and ends with the
# summary line "N passed, N failed". Exit status 1 when anything failed.
BUILD=${1:-build}
pass=0; fail=0; bad=""
for t in "$BUILD"/tests/test_*; do
	[ -x "$t" ] || continue
	name=$(basename "$t")
	out=$(timeout 600 "$t" 2>&1); rc=$?
	printf '%s\n' "$out" | grep -E '^\[ *(RUN|OK|FAILED|PASSED|SKIPPED|ERROR) *\]|^\[==========\]' \
		| grep -v '^\[ RUN' | grep -v '^\[       OK' || true
	p=$(printf '%s\n' "$out" | sed -n 's/^\[  PASSED  \] \([0-9]*\) test.*/\1/p' | tail -n 1)
	f=$(printf '%s\n' "$out" | sed -n 's/^\[  FAILED  \] \([0-9]*\) test.*/\1/p' | tail -n 1)
	pass=$((pass + ${p:-0})); fail=$((fail + ${f:-0}))
	if [ $rc -ne 0 ]; then
		[ -z "$f" ] && fail=$((fail + 1))
		bad="$bad $name"
		printf '%s\n' "$out" | tail -n 30
		echo "FAILED: $name (exit $rc)"
	fi
done
[ -n "$bad" ] && echo "failing test programs:$bad"
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ] && [ -z "$bad" ]
