#!/usr/bin/env bash
# libFuzzer campaigns on the scene loader, the SWC reader, the spectrum CSV reader and the units parser
# (tests/fuzz, docs/reliability.md). Needs clang and its runtime: bash scripts/install-deps.sh --fuzz.
#
#   bash scripts/fuzz.sh build                 # configure and build build-fuzz (clang, ASan+UBSan, coverage)
#   bash scripts/fuzz.sh run NAME SECONDS      # fuzz one harness; findings go to build-fuzz/findings/NAME
#   bash scripts/fuzz.sh merge NAME            # minimise the campaign's corpus into tests/fuzz/corpus/NAME
#
# NAME is scene_loader, swc_reader, spectra_csv or units. A run resumes from the campaign's working
# corpus (build-fuzz/corpus/NAME) and the seeds in tests/fuzz/corpus/NAME, and prints libFuzzer's
# final statistics (executions, coverage).
set -euo pipefail
cd "$(dirname "$0")/.."
cmd=${1:-}
case "$cmd" in
  build)
    CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithAssert -DFLUOROSIM_BUILD_FUZZERS=ON \
      -DFLUOROSIM_BUILD_TESTS=OFF -DFLUOROSIM_BUILD_BENCH=OFF >/dev/null
    ninja -C build-fuzz -j2 fuzz_scene_loader fuzz_swc_reader fuzz_spectra_csv fuzz_units
    ;;
  run)
    name=$2 seconds=$3
    case "$name" in
      scene_loader) maxlen=16384 ;;
      swc_reader|spectra_csv) maxlen=8192 ;;
      units) maxlen=256 ;;
      *) echo "fuzz.sh: unknown harness $name" >&2; exit 2 ;;
    esac
    mkdir -p "build-fuzz/corpus/$name" "build-fuzz/findings/$name"
    # Leaks inside Assimp are not ours (scripts/lsan.supp).
    export LSAN_OPTIONS="suppressions=$PWD/scripts/lsan.supp:print_suppressions=0"
    "build-fuzz/tests/fuzz/fuzz_$name" "build-fuzz/corpus/$name" "tests/fuzz/corpus/$name" -max_total_time="$seconds" \
      -max_len=$maxlen -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=1024 -print_final_stats=1 \
      -artifact_prefix="build-fuzz/findings/$name/"
    ;;
  merge)
    name=$2
    mkdir -p "build-fuzz/merged/$name"
    "build-fuzz/tests/fuzz/fuzz_$name" -merge=1 "build-fuzz/merged/$name" "tests/fuzz/corpus/$name" "build-fuzz/corpus/$name"
    ;;
  *)
    sed -n '2,13p' "$0" >&2
    exit 2
    ;;
esac
