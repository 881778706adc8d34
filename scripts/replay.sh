#!/usr/bin/env bash
# Replay an MCAP recording onto the ROS graph.
#
#   scripts/replay.sh run.mcap [--rate X] [--topics /a /b ...] [--loop] [--clock]
#                              [--wait S] [--linger S] [-- extra --ros-args ...]
#   scripts/replay.sh run.mcap --offline [--params FILE]... [--out DIR]
#   scripts/replay.sh estimate.json --offline [--params FILE]... [--out DIR]
#
# Publishes the recorded messages at their recorded timing (scaled by --rate)
# with their recorded QoS (latched topics stay latched); --clock also
# publishes /clock from the recorded times. Discovery stays on this host
# (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) unless you set another value.
# --offline starts no graph: it rebuilds the estimate from the recorded
# contacts with the run's parameters (plus --params) and rewrites the report;
# given a saved estimate (estimate.json of a run folder) it rebuilds that estimate
# (--params: other gpis_estimator parameters), measures and exports it.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
usage() { sed -n '2,16p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; }
die() { echo "replay.sh: error: $*" >&2; exit 2; }

[ $# -ge 1 ] || { usage >&2; exit 2; }
case "$1" in -h|--help) usage; exit 0 ;; esac
BAG="$1"; shift
OFFLINE=false; PARAMS=(); RATE=1.0; LOOP=false; CLOCK=false; WAIT=2.0; LINGER=0.0; TOPICS=(); EXTRA=()
while [ $# -gt 0 ]; do
  case "$1" in
    --rate) [ $# -ge 2 ] || die "--rate needs a value"; RATE="$2"; shift 2 ;;
    --loop) LOOP=true; shift ;;
    --clock) CLOCK=true; shift ;;
    --wait) [ $# -ge 2 ] || die "--wait needs seconds"; WAIT="$2"; shift 2 ;;
    --linger) [ $# -ge 2 ] || die "--linger needs seconds"; LINGER="$2"; shift 2 ;;
    --topics) shift; while [ $# -gt 0 ] && [ "${1#--}" = "$1" ]; do TOPICS+=("$1"); shift; done
              [ ${#TOPICS[@]} -gt 0 ] || die "--topics needs at least one topic" ;;
    --offline) OFFLINE=true; shift ;;
    --params) [ $# -ge 2 ] || die "--params needs a file"; PARAMS+=(--params "$2"); shift 2 ;;
    --out) [ $# -ge 2 ] || die "--out needs a folder"; PARAMS+=(--out "$2"); shift 2 ;;
    --) shift; EXTRA=("$@"); break ;;
    -h|--help) usage; exit 0 ;;
    *) die "unknown option '$1' (see --help)" ;;
  esac
done
[ -f "$BAG" ] || die "recording '$BAG' not found"
case "$BAG" in *.json) [ "$OFFLINE" = true ] || die "'$BAG' is a saved estimate, not a recording: use --offline" ;; esac

"$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "${TACTILE_VENV:-$ROOT/.venv}/tactile.env"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
# Check the options against the player's parameter table (and any --params file
# against every node's) before anything starts: exit 2 with one line per problem.
check=(--rate "$RATE" --wait "$WAIT" --linger "$LINGER")
for ((i = 0; i < ${#PARAMS[@]}; i += 2)); do
  [ "${PARAMS[$i]}" = --params ] && check+=(--params "${PARAMS[$((i + 1))]}")
done
python -m tactile_bringup.launch_plan replay "${check[@]}" || exit 2

# ROS double parameters need a decimal point ("2" would be an integer).
as_double() { case "$1" in *.*|*e*|*E*) echo "$1" ;; *) echo "$1.0" ;; esac; }
RATE="$(as_double "$RATE")"; WAIT="$(as_double "$WAIT")"; LINGER="$(as_double "$LINGER")"
if [ "$OFFLINE" = true ]; then  # no graph: rebuild the estimate and the report from the recording
  case "$BAG" in *.json) exec python -m tactile_bringup.state_replay "$BAG" "${PARAMS[@]}" ;; esac
  exec python -m tactile_bringup.reanalyse "$BAG" "${PARAMS[@]}"
fi

ARGS=(--ros-args --params-file "$ROOT/src/tactile_bringup/config/player.yaml"
      -p "bag:=$(cd "$(dirname "$BAG")" && pwd)/$(basename "$BAG")" -p "rate:=$RATE" -p "loop:=$LOOP"
      -p "clock:=$CLOCK" -p "wait_for_subscribers_s:=$WAIT" -p "linger_s:=$LINGER")
if [ ${#TOPICS[@]} -gt 0 ]; then
  list="$(printf "'%s'," "${TOPICS[@]}")"
  ARGS+=(-p "topics:=[${list%,}]")
fi
exec player "${ARGS[@]}" "${EXTRA[@]}"
