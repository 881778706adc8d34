#!/usr/bin/env bash
# Benchmarks: scripts/bench.sh gpis|planner|arm|explore|strategies|runs|soak [args...]
# Each prints ratios measured in one run; --json FILE writes the figures too.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "${TACTILE_VENV:-$ROOT/.venv}/tactile.env"
what="${1:-}"
shift || true
case "$what" in
  gpis)    exec python -m tactile_gpis.bench "$@" ;;
  planner) exec python -m tactile_planner.bench "$@" ;;
  arm)     exec python -m tactile_driver.arm_bench "$@" ;;
  explore) exec tactile-explore-offline "$@" ;;
  strategies) exec tactile-benchmark "$@" ;;  # strategies x objects x seeds offline, with a progress bar
  runs)    # runs N [explore.sh args]: N graph runs in a row (seeds 1..N); how many completed their budget
    n="${1:-20}"; shift || true
    [[ "$n" =~ ^[1-9][0-9]*$ ]] || { echo "bench.sh runs: N must be a positive integer" >&2; exit 2; }
    dir="$(mktemp -d "${TMPDIR:-/tmp}/tactile-runs.XXXXXX")"; ok=0; start=$SECONDS
    args_q="$(printf ' %q' "$@")"  # the explore.sh arguments, quoted for a repeat command line
    for s in $(seq 1 "$n"); do
      t0=$SECONDS
      if bash "$ROOT/scripts/explore.sh" --out "$dir/seed$s" --seed "$s" "$@" > "$dir/seed$s.log" 2>&1 \
          && grep -q '"stopped_because": "touch budget"' "$dir/seed$s/report.json"; then
        ok=$((ok + 1)); verdict=completed
      else
        verdict="FAILED (see $dir/seed$s.log); repeat with: scripts/explore.sh --seed $s$args_q"
      fi
      left=$(( (SECONDS - start) * (n - s) / s ))  # progress: runs done, failed, time left
      echo "[$s/$n, $((s - ok)) failed, ~$((left / 60)) min $((left % 60)) s left] run $s (seed $s) in $((SECONDS - t0)) s: $verdict" >&2
    done
    echo "$ok/$n graph runs completed their touch budget (runs in $dir)"
    [ "$ok" = "$n" ] ;;
  soak)    # long 2D and 3D graph runs: RSS per node, MCAP size, decision time per touch (docs/reliability.md)
    TACTILE_ROOT="$ROOT" exec python -m tactile_bringup.soak "$@" ;;
  *) echo "usage: scripts/bench.sh gpis|planner|arm|explore|strategies|runs|soak [options]  (--help for each)" >&2; exit 2 ;;
esac
