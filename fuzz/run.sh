#!/usr/bin/env bash
# Fuzzes each TARGET for SECONDS, one after another, on one core at low priority, and prints
# per target: seconds, executions, crashes (fuzz/README.md).
#
#   fuzz/run.sh SECONDS TARGET...        e.g. fuzz/run.sh 900 solvers estimate
#
# Environment: FUZZ_OUT (where corpus/ and artifacts/ live; default fuzz/), FUZZ_TARGET_DIR
# (cargo's target dir; default fuzz/target), ORT_DYLIB_PATH (default: the .venv wheel's
# library, for shape_model).
set -u
here="$(cd "$(dirname "$0")" && pwd)"
root="$(dirname "$here")"
secs="$1"
shift
out="${FUZZ_OUT:-$here}"
target_dir="${FUZZ_TARGET_DIR:-$here/target}"
export RUSTC_BOOTSTRAP=1 # cargo-fuzz needs -Zsanitizer; the project's toolchain is stable
if [ -z "${ORT_DYLIB_PATH:-}" ]; then
    ORT_DYLIB_PATH="$("$root/.venv/bin/python" -c 'import affcorr.shape as s; print(s.find_ort_library() or "")')"
    export ORT_DYLIB_PATH
fi
for t in "$@"; do
    logs="$target_dir/fuzz-logs/$t-$(date +%Y%m%dT%H%M%S)"
    mkdir -p "$out/corpus/$t" "$out/artifacts/$t" "$logs"
    start=$(date +%s)
    # -jobs=1: one worker process (its log is fuzz-0.log). A crash ends the worker; the loop
    # restarts it on the grown corpus until SECONDS have passed, so later bugs are found too.
    run=0
    while left=$((secs - ($(date +%s) - start))) && [ "$left" -gt 20 ]; do
        mkdir -p "$logs/$run"
        t0=$(date +%s)
        (cd "$logs/$run" && nice -n 10 cargo fuzz run --fuzz-dir "$here" --target-dir "$target_dir" \
            "$t" "$out/corpus/$t" -- -jobs=1 -max_total_time="$left" -timeout=10 \
            -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$out/artifacts/$t/" \
            >cargo.log 2>&1)
        run=$((run + 1))
        # A worker that ends within seconds twice in a row is a broken build or a crash on
        # the corpus itself: stop rather than spin.
        if [ $(($(date +%s) - t0)) -lt 10 ]; then
            quick=$((${quick:-0} + 1))
            [ "$quick" -ge 2 ] && echo "$t: stopped, worker ended at once (see $logs)" && break
        else
            quick=0
        fi
    done
    wall=$(($(date +%s) - start))
    execs=$(grep -h "stat::number_of_executed_units" "$logs"/*/fuzz-*.log 2>/dev/null |
        awk '{s += $2} END {print s + 0}')
    crashes=$(find "$out/artifacts/$t" -type f -newermt "@$start" | wc -l)
    echo "$t: ${wall}s wall, $execs executions, $run runs, $crashes new artifacts, logs $logs"
done
