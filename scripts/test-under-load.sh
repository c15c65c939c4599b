#!/usr/bin/env bash
# The README's test command on a busy machine: `cargo test` (every test binary, no fail-fast)
# RUNS times in a row while stress-ng keeps STRESS_CPUS CPU hogs running beside it (4 on a
# 2-core machine: the tests get about a third of the CPU). Any failure fails the script, with
# the run's log kept. Tests wait for events with generous deadlines, never for the clock; this
# is how that is checked (README, "Tests").
#
#   bash scripts/test-under-load.sh            # 3 runs beside `stress-ng --cpu 4`
#   RUNS=1 STRESS_CPUS=8 bash scripts/test-under-load.sh
#
# Needs stress-ng (`apt-get install stress-ng`). The build comes first, on a quiet machine.
set -euo pipefail
cd "$(dirname "$0")/.."

runs="${RUNS:-3}"
cpus="${STRESS_CPUS:-4}"
command -v stress-ng >/dev/null || { echo "stress-ng is required: apt-get install stress-ng"; exit 1; }

echo "== building the tests (quiet)"
cargo test --locked --no-run -q

logs="$(mktemp -d "${TMPDIR:-/tmp}/tacmesh-load.XXXXXX")"
stress-ng --cpu "$cpus" --quiet &
stress=$!
trap 'kill "$stress" 2>/dev/null || true' EXIT

for run in $(seq 1 "$runs"); do
  echo "== run $run of $runs beside stress-ng --cpu $cpus (load $(cut -d' ' -f1-3 /proc/loadavg))"
  started=$SECONDS
  if cargo test --locked --no-fail-fast >"$logs/run$run.log" 2>&1; then
    passed=$(grep -Eo '^test result: ok\. [0-9]+ passed' "$logs/run$run.log" |
      awk '{ sum += $4 } END { print sum + 0 }')
    echo "run $run: $passed passed, 0 failed in $((SECONDS - started)) s"
  else
    echo "run $run FAILED after $((SECONDS - started)) s; its log: $logs/run$run.log"
    grep -E '^test .* FAILED$|^---- |panicked at' "$logs/run$run.log" | head -n 40
    exit 1
  fi
done
rm -rf "$logs"
echo "== $runs of $runs runs passed under load"
