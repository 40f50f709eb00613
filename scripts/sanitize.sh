#!/usr/bin/env bash
# Builds Fluorosim with AddressSanitizer and UndefinedBehaviorSanitizer (gcc) in ./build-asan and
# runs the whole test suite there (docs/reliability.md has the latest figures). Any sanitizer report
# fails the run: UBSan stops at its first report, ASan at its first error, and LeakSanitizer checks
# every test process at exit.
#
#   bash scripts/sanitize.sh               # build, then run every test
#   bash scripts/sanitize.sh --build-only  # only build
#   bash scripts/sanitize.sh --test-only [ctest args, e.g. -R Cli]
set -euo pipefail
cd "$(dirname "$0")/.."
mode=all
case "${1:-}" in
  --build-only) mode=build; shift ;;
  --test-only) mode=test; shift ;;
esac

if [[ $mode != test ]]; then
  bash scripts/install-deps.sh
  flags="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
  # -O1 -g: readable reports at a bearable speed. Benchmarks are left out.
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithAssert -DCMAKE_CXX_FLAGS_RELWITHASSERT="-O1 -g" \
    -DCMAKE_C_FLAGS_RELWITHASSERT="-O1 -g" -DCMAKE_CXX_FLAGS="$flags" -DCMAKE_C_FLAGS="$flags" \
    -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" -DFLUOROSIM_BUILD_BENCH=OFF >/dev/null
  ninja -C build-asan -j2
fi

if [[ $mode != build ]]; then
  export ASAN_OPTIONS="detect_leaks=1:abort_on_error=0:strict_string_checks=1:detect_stack_use_after_return=1"
  export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
  export LSAN_OPTIONS="suppressions=$PWD/scripts/lsan.supp:print_suppressions=0"
  log=build-asan/sanitize-ctest.log
  status=0
  (cd build-asan && ctest --output-on-failure -j2 --timeout 3000 "$@") >"$log" 2>&1 || status=$?
  tail -n 5 "$log"
  reports=$(grep -c -E "runtime error:|ERROR: AddressSanitizer|ERROR: LeakSanitizer" "$log" || true)
  echo "sanitize: $reports sanitizer reports (log: $log)"
  if [[ $status -ne 0 || $reports -ne 0 ]]; then exit 1; fi
fi
