#!/usr/bin/env bash
# ctest Package.FindPackageConsumer: installs the build tree into a temporary prefix, builds
# tests/package/consumer against it with find_package(Fluorosim), and runs it.
# Usage: consumer_test.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
build=$1 source=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build" --prefix "$work/prefix" > "$work/install.log"
test -x "$work/prefix/bin/fluorosim"
test -f "$work/prefix/share/fluorosim/spectra/dyes.json"
cmake -S "$source/tests/package/consumer" -B "$work/build" -DCMAKE_PREFIX_PATH="$work/prefix" -DCMAKE_BUILD_TYPE=Release > "$work/configure.log"
cmake --build "$work/build" -j2 > "$work/build.log"
"$work/build/consumer"
