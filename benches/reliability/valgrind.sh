#!/usr/bin/env bash
# Valgrind memcheck over Rust test binaries that call the estimators (affcorr-ransac
# tests/determinism.rs: every estimate_* and _batch form under rayon pools of 1, 2, 4 threads)
# and the runner and images (affcorr-runner tests/shape_model.rs, affcorr-image tests/images.rs: ONNX Runtime
# sessions, inference, contract checks, image decoding). Prints each binary's LEAK SUMMARY and
# ERROR SUMMARY; the figures go to docs/reliability.md. Slow (tens of minutes): not run in CI.
#
#   bash benches/reliability/valgrind.sh [PACKAGE:TEST[:FILTER]...]   (from the repository root)
#
# Without arguments: affcorr-ransac:determinism affcorr-runner:shape_model affcorr-image:images.
# FILTER is passed to the test binary (a test-name substring).
#
# Needs valgrind (apt-get install valgrind; setup.sh in this folder does it) and .venv's
# ONNX Runtime for the runner tests.
set -eu
cd "$(dirname "$0")/../.."
command -v valgrind >/dev/null || { echo "valgrind is missing: bash benches/reliability/setup.sh"; exit 1; }
: "${ORT_DYLIB_PATH:=$(.venv/bin/python -c 'import affcorr.shape as s; print(s.find_ort_library() or "")')}"
export ORT_DYLIB_PATH
out="${VALGRIND_OUT:-target/valgrind}"
mkdir -p "$out"
binary() { # package test -> the test executable
    cargo test --locked -p "$1" --test "$2" --no-run --message-format=json 2>/dev/null |
        python3 -c 'import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["kind"] == ["test"]:
        print(m["executable"])' | tail -1
}
specs=("$@")
[ ${#specs[@]} -gt 0 ] || specs=(affcorr-ransac:determinism affcorr-runner:shape_model affcorr-image:images)
for spec in "${specs[@]}"; do
    IFS=: read -r pkg test filter <<<"$spec"
    exe="$(binary "$pkg" "$test")"
    log="$out/$test${filter:+-$filter}.log"
    # One test thread: valgrind serialises threads anyway, and the output stays readable.
    (cd "crates/$pkg" && nice -n 10 valgrind --leak-check=full --show-leak-kinds=definite,indirect \
        --errors-for-leak-kinds=definite --error-exitcode=0 --log-file="$PWD/../../$log" \
        "$exe" --test-threads=1 ${filter:+"$filter"} >"$PWD/../../$log.out" 2>&1) || true
    echo "== $pkg $test ${filter:-(all tests)}: $(grep -h "^test result" "$log.out")"
    grep -E "definitely lost|indirectly lost|possibly lost|still reachable|ERROR SUMMARY" "$log" |
        sed 's/^==[0-9]*== *//'
done
