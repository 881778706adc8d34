#!/usr/bin/env bash
# The test command: set up the virtualenv, then run every test suite.
# Extra arguments go to pytest (e.g. scripts/test.sh tests/gpis -k incremental).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "${TACTILE_VENV:-$ROOT/.venv}/tactile.env"
# Graph tests pick their own ROS_DOMAIN_ID; discovery never leaves this host.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
cd "$ROOT"
exec python -m pytest "$@"
