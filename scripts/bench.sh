#!/usr/bin/env bash
# Benchmarks: scripts/bench.sh gpis|planner|arm|explore [args...]
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
  *) echo "usage: scripts/bench.sh gpis|planner|arm|explore [options]  (--help for each)" >&2; exit 2 ;;
esac
