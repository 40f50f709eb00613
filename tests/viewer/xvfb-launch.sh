#!/usr/bin/env bash
# Runs a command under a private Xvfb (Mesa llvmpipe renders through it). The server picks a free
# display number itself (-displayfd), so simultaneous runs -- ctest -j, or anyone else on the machine
# using xvfb-run -a, which can hand two runs the same number -- never share or lose their display.
# Usage: xvfb-launch.sh COMMAND [ARG...]; exits with the command's exit code.
set -uo pipefail
number=$(mktemp)
Xvfb -displayfd 3 -screen 0 1280x1024x24 -nolisten tcp -noreset 3>"$number" 2>/dev/null &
server=$!
for _ in $(seq 100); do
  [[ -s "$number" ]] && break
  kill -0 "$server" 2>/dev/null || break
  sleep 0.05
done
if [[ ! -s "$number" ]]; then
  echo "xvfb-launch: Xvfb did not start" >&2
  kill "$server" 2>/dev/null
  rm -f "$number"
  exit 1
fi
export DISPLAY=":$(head -n1 "$number")"
rm -f "$number"
"$@"
status=$?
kill "$server" 2>/dev/null
wait "$server" 2>/dev/null
exit "$status"
