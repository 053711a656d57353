#!/usr/bin/env bash
# Tools of the reliability benchmarks: valgrind (valgrind.sh) and GNU time
# (python -m affcorr_bench.reliability.peak_memory).
set -eu
missing=()
command -v valgrind >/dev/null || missing+=(valgrind)
[ -x /usr/bin/time ] || missing+=(time)
if [ ${#missing[@]} -gt 0 ]; then
    apt-get update -qq && apt-get install -y -qq "${missing[@]}"
fi
