#!/usr/bin/env bash
# Production-line check of a batch of carriages (an example for CI systems).
# Usage: ci-example.sh SPEC.toml RECORDING...   (writes results.csv, junit.xml, results.jsonl, joints.bdf)
set -u
spec=$1; shift
guidefit identify "$@" --jobs 2 --check "$spec" \
    --summary results.csv --junit junit.xml --json > results.jsonl
status=$?
if [ "$status" -ne 2 ]; then
    # export the carriages that were identified (a failed check still has parameters);
    # export exits 1 when it left out a carriage identify failed on (named on stderr)
    guidefit export results.jsonl --format nastran -o joints.bdf
    case $? in 0) ;; 1) [ "$status" -eq 0 ] && status=1 ;; *) status=2 ;; esac
fi
echo "line check finished with exit status $status (0 pass, 1 out of tolerance, 2 bad input)"
exit "$status"
