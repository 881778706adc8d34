#!/usr/bin/env bash
# The main job: set up, start the node graph, explore an object, record to MCAP.
#
#   scripts/explore.sh [--object NAME|FILE] [--mode 2d|3d] [--strategy NAME] [--alpha A]
#                      [--touches N] [--touch poke|slide] [--seed S] [--out DIR] [--real-time-factor X]
#                      [--rig sim|hardware] [--sensor-port DEV] [--params FILE]... [--yes]
#   scripts/explore.sh --resume RUN_DIR [--touches N] [--real-time-factor X] [--rig ...] [--yes]
#
# Leaves in runs/<timestamp>/ (or --out): run.mcap, report.json, progress.png,
# the exports (shape.*, contacts.ply, estimate.json), params/ (every parameter file the nodes got)
# and logs/ (one per node). Ctrl-C stops every node, finalises the MCAP and
# still writes the report so far. --resume continues an interrupted run from its
# recorded observations, with its parameters (a new --touches budget may extend
# it), into the same folder (run.resume<k>.mcap, logs/resume<k>/); the report
# covers the whole run.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

usage() { sed -n '2,15p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; }

mode=2d object="" strategy="" alpha="" touches="" touch="" seed=0 out="" rtf=4.0 rig=sim
sensor_port="/dev/ttyUSB0" yes=0 user_params=() resume="" fixed=() rig_set=0
die() { echo "explore.sh: error: $* (see --help)" >&2; exit 2; }
need() { [ $# -ge 2 ] || die "$1 needs a value"; }  # need "$@": the option has a value
# Values are checked (type, range, contradictions) by launch_plan below, against
# the nodes' parameter tables, before any node starts or anything is written.
while [ $# -gt 0 ]; do
  case "$1" in
    --object) need "$@"; object="$2"; fixed+=("$1"); shift 2 ;;
    --mode) need "$@"; mode="$2"; fixed+=("$1"); shift 2 ;;
    --strategy) need "$@"; strategy="$2"; fixed+=("$1"); shift 2 ;;
    --alpha) need "$@"; alpha="$2"; fixed+=("$1"); shift 2 ;;
    --touches) need "$@"; touches="$2"; shift 2 ;;
    --touch) need "$@"; touch="$2"; fixed+=("$1"); shift 2 ;;
    --seed) need "$@"; seed="$2"; fixed+=("$1"); shift 2 ;;
    --out) need "$@"; out="$2"; fixed+=("$1"); shift 2 ;;
    --resume) need "$@"; resume="$2"; shift 2 ;;
    --real-time-factor) need "$@"; rtf="$2"; shift 2 ;;
    --rig) need "$@"; rig="$2"; rig_set=1; shift 2 ;;
    --sensor-port) need "$@"; sensor_port="$2"; shift 2 ;;
    --params) need "$@"; [ -f "$2" ] || die "--params $2: no such parameter file"
              user_params+=("$(realpath -m "$2")"); fixed+=("$1"); shift 2 ;;
    --yes|-y) yes=1; shift ;;
    -h|--help) usage; exit 0 ;;
    *) die "unknown option '$1'" ;;
  esac
done
case "$rig" in sim|hardware) ;; *) die "--rig $rig: must be sim or hardware" ;; esac
if [ -n "$resume" ] && [ "${#fixed[@]}" -gt 0 ]; then
  die "--resume continues a run with its own object, mode, strategy, seed, parameters and folder: drop ${fixed[*]}"
fi

"$ROOT/scripts/setup.sh"
# shellcheck disable=SC1091
source "${TACTILE_VENV:-$ROOT/.venv}/tactile.env"
# Discovery stays on this host unless the user chose a range (a multi-machine rig).
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"

rec_base=run session=""  # a resumed run's session k records into run.resume<k>.mcap, logs in logs/resume<k>/
if [ -n "$resume" ]; then
  run_dir="$(realpath -m "$resume")"
  # Rebuild the run so far from its recordings and write the next session's bundle (exit 2 on a bad folder).
  resume_args=(--out "$run_dir" --real-time-factor "$rtf"); [ -n "$touches" ] && resume_args+=(--touches "$touches")
  mapfile -t files < <(python -m tactile_bringup.launch_plan resume "${resume_args[@]}") || exit 2
  [ "${#files[@]}" -gt 1 ] || exit 2
  read -r session mode resumed_rig <<< "${files[0]}"
  files=("${files[@]:1}")
  [ "$rig_set" = 1 ] || rig="$resumed_rig"
  rec_base="run.resume$session"
else
  run_dir="$(realpath -m "${out:-$ROOT/runs/$(date +%Y%m%d-%H%M%S)}")"
  if [ -e "$run_dir/run.mcap" ]; then
    echo "explore.sh: $run_dir already holds a run; choose another --out (or --resume it)" >&2; exit 2
  fi
  # Resolve and check the experiment (exit 2, nothing written, on a bad value);
  # the same files go to every node.
  plan_args=(--mode "$mode" --seed "$seed" --rig "$rig" --real-time-factor "$rtf" --out "$run_dir")
  [ -n "$object" ] && plan_args+=(--object "$object")
  [ -n "$strategy" ] && plan_args+=(--strategy "$strategy")
  [ -n "$alpha" ] && plan_args+=(--alpha "$alpha")
  [ -n "$touches" ] && plan_args+=(--touches "$touches")
  [ -n "$touch" ] && plan_args+=(--touch "$touch")
  for f in "${user_params[@]}"; do plan_args+=(--params "$f"); done
  mapfile -t files < <(python -m tactile_bringup.launch_plan plan "${plan_args[@]}") || exit 2
  [ "${#files[@]}" -gt 0 ] || exit 2
fi
log_dir="$run_dir/logs${session:+/resume$session}"
mkdir -p "$log_dir"
case "$rtf" in *.*|*e*|*E*) ;; *) rtf="$rtf.0" ;; esac  # a ROS double parameter needs the decimal point
params_args=()
for f in "${files[@]}"; do params_args+=(--params-file "$f"); done

sim_time=false
sensor_link="$sensor_port"
if [ "$rig" = sim ]; then
  sim_time=true
  sensor_link="$run_dir/sensor.pty"
fi

# What this launch decides (paths, simulated time, the rig) goes in a last file with
# node sections: rcl lets a node section of a file beat a '-p' given on the command
# line in some cases (e.g. with a remapped node name), so no '-p' is used at all.
launch_yaml="$run_dir/params/99_launch${session:+_resume$session}.yaml"
cat > "$launch_yaml" <<YAML
# Written by scripts/explore.sh for this run.
/**:
  ros__parameters:
    use_sim_time: $sim_time
recorder:
  ros__parameters:
    output: "$run_dir/$rec_base.mcap"
    exclude: ["/rosout", "/parameter_events"]
sim_rig:
  ros__parameters:
    real_time_factor: $rtf
    sensor_link_path: "$sensor_link"
tactile_sensor:
  ros__parameters:
    port: "$sensor_link"
$([ "$rig" = sim ] && printf '    %s\n' "device_clock_is_ros_time: true  # the simulated device stamps simulated time" "max_frame_age_s: 5.0  # simulated seconds: the rig waits for the driver (lock-step), frames are never that old" "pose_wait_s: 5.0  # simulated seconds: a contact waits for the pose at its time (determinism under load)")
$([ "$rig" = sim ] && printf '%s\n' "arm_commander:" "  ros__parameters:" "    watchdog_timeout_s: 2.0  # the simulator, not an arm: on a loaded machine its joint states stall for a second" "    start_lead_s: 0.5  # timed starts on the rig's 10 ms tick: every motion sampled identically (determinism)" "    start_grid_s: 0.01")
explorer:
  ros__parameters:
    params_files: [$(printf '"%s", ' "${files[@]}" | sed 's/, $//')]
    out_dir: "$run_dir"
    mode: "$mode"
    evaluate: $([ "$rig" = sim ] && echo true || echo false)
$([ -n "$session" ] && printf '%s\n' "    resume_from: \"$run_dir/resume$session\"" "gpis_estimator:" "  ros__parameters:" "    initial_observations_file: \"$run_dir/resume$session/observations.csv\"")
YAML
params_args+=(--params-file "$launch_yaml")

names=() pids=() restarts=()
MAX_RESTARTS="${TACTILE_MAX_RESTARTS:-3}"  # per node; then a death ends the run
launch() {  # launch INDEX: (re)start node names[INDEX] in the background, appending to logs/<name>.log
  local i="$1" name="${names[$1]}" extra=()
  if [ "$name" = recorder ] && [ "${restarts[$i]}" -gt 0 ]; then
    # A restarted recorder writes the next file of the run: durable topics hand it their history.
    local part="$run_dir/params/99_recorder${session:+_resume$session}_${restarts[$i]}.yaml"
    printf 'recorder:\n  ros__parameters:\n    output: "%s"\n' "$run_dir/$rec_base.${restarts[$i]}.mcap" > "$part"
    extra=(--params-file "$part")
  fi
  local file_limit_kib=""  # fault injection (tests): the first recorder's disk is full at this size (EFBIG)
  [ "$name" = recorder ] && [ "${restarts[$i]}" = 0 ] && file_limit_kib="${TACTILE_RECORDER_FILE_LIMIT_KIB:-}"
  # exec: the subshell becomes the node (same pid)
  ( [ -z "$file_limit_kib" ] || ulimit -f "$file_limit_kib"; exec "$name" --ros-args "${params_args[@]}" "${extra[@]}" ) \
    >> "$log_dir/$name.log" 2>&1 &
  pids[$i]=$!
}
late_nodes=" ${TACTILE_LATE_NODES:-} " deferred=()  # fault injection (tests): start these nodes late
start() {  # start EXECUTABLE: a node in the background (its own node name), logging to logs/<name>.log
  local name="$1"
  if [[ "$late_nodes" == *" $name "* ]] && [ "${2:-}" != now ]; then deferred+=("$name"); return; fi
  : > "$log_dir/$name.log"  # exists now (the redirection below runs in the background job)
  names+=("$name"); restarts+=(0)
  launch $((${#names[@]} - 1))
}
recover_recording() {  # recover_recording FILE: rewrite a recording cut by a crash so that all of it reads
  local f="$1" cut_bytes
  cut_bytes=$(stat -c %s "$f" 2>/dev/null || echo "?")  # what the recorder wrote; the rewrite adds indexes
  python -m tactile_bringup.mcap_recorder --recover "$f" "$f.recovering" >> "$log_dir/recorder.log" 2>&1 \
    && mv "$f.recovering" "$f" \
    && echo "explore.sh: $(basename "$f") was cut at $cut_bytes bytes by the recorder's crash: recovered (every message up to the cut, with the index a finished file has)" >&2 \
    || { rm -f "$f.recovering"; echo "explore.sh: could not recover $(basename "$f"); see logs/recorder.log" >&2; }
}

stopping=0
stop_all() {  # SIGINT to every node (explorer first, recorder last), then wait; escalate if needed
  [ "$stopping" = 1 ] && return; stopping=1
  local i pid
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do kill -INT "${pids[$i]}" 2>/dev/null || true; done
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do
    pid="${pids[$i]}"
    for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    if kill -0 "$pid" 2>/dev/null; then
      echo "explore.sh: ${names[$i]} did not stop on SIGINT; terminating" >&2
      kill -TERM "$pid" 2>/dev/null || true; sleep 2; kill -KILL "$pid" 2>/dev/null || true
    fi
  done
}
on_signal() {
  echo; echo "explore.sh: interrupted: stopping the graph (the report so far is kept)" >&2
  # The explorer writes its report on SIGINT; stop it first, the recorder last.
  stop_all; summary; exit 130
}
summary() {
  echo "run folder: $run_dir"
  local f
  for f in "$run_dir"/run.mcap "$run_dir"/run.*.mcap "$run_dir"/{report.json,progress.png,shape.csv,shape.ply,shape.stl,shape.obj,contacts.ply,estimate.json}; do
    [ -e "$f" ] && echo "  $(basename "$f")"
  done
  return 0
}
trap on_signal INT TERM

echo "ROS_DOMAIN_ID=$ROS_DOMAIN_ID, discovery $ROS_AUTOMATIC_DISCOVERY_RANGE; logs in $log_dir" >&2
start recorder
if [ "$rig" = sim ]; then
  start sim_rig
else
  python -m tactile_bringup.launch_plan wait-joint-states --timeout 15 || { stop_all; exit 1; }
  if [ ! -e "$sensor_port" ]; then
    echo "explore.sh: sensor device $sensor_port does not exist (--sensor-port)" >&2; stop_all; exit 1
  fi
fi
start tactile_sensor
start gpis_estimator
start soc_planner
# viz: viewer markers and the robot description (docs/recording.md)
start viz
if [ "$rig" = hardware ] && [ "$yes" != 1 ]; then
  read -r -p "The arm will move to the start pose and touch the object. Continue? [y/N] " answer < /dev/tty
  case "$answer" in y|Y|yes) ;; *) echo "explore.sh: aborted before any motion" >&2; stop_all; exit 1 ;; esac
fi
start arm_commander
start explorer
explorer_pid="${pids[-1]}"
if [ "${#deferred[@]}" -gt 0 ]; then
  echo "explore.sh: fault injection: starting ${deferred[*]} ${TACTILE_LATE_START_S:-5} s late" >&2
  sleep "${TACTILE_LATE_START_S:-5}"
  for n in "${deferred[@]}"; do start "$n" now; done
fi
# Show the explorer's progress here while it runs.
tail -n +1 -f "$log_dir/explorer.log" --pid "$explorer_pid" &
tail_pid=$!

# Supervise (as ros2 launch's respawn): the run ends when the explorer exits. A node
# that dies is started again, up to MAX_RESTARTS times, and recovers its state from the
# durable topics (docs/reliability.md); a node that exits with status 2 (bad parameters)
# or dies too often ends the run.
status=0
cut_recordings=()
while kill -0 "$explorer_pid" 2>/dev/null; do
  for i in "${!pids[@]}"; do
    [ "${names[$i]}" = explorer ] && continue
    kill -0 "${pids[$i]}" 2>/dev/null && continue
    code=0; wait "${pids[$i]}" 2>/dev/null || code=$?
    if [ "$code" = 0 ] || [ "$code" = 130 ]; then
      # A node stops cleanly only when told to (SIGINT from Ctrl-C, which reaches the whole process group,
      # sometimes before bash runs its trap): the graph is being stopped, not crashing. Never restart it.
      on_signal
    fi
    if [ "$code" = 2 ] || [ "${restarts[$i]}" -ge "$MAX_RESTARTS" ]; then
      echo "explore.sh: ${names[$i]} exited unexpectedly (status $code); see $log_dir/${names[$i]}.log:" >&2
      tail -n 15 "$log_dir/${names[$i]}.log" >&2
      status=1
      break 2
    fi
    restarts[$i]=$((restarts[$i] + 1))
    echo "explore.sh: ${names[$i]} died (status $code): restarting it (${restarts[$i]}/$MAX_RESTARTS)" >&2
    if [ "${names[$i]}" = recorder ]; then
      prev="$run_dir/$rec_base.mcap"; [ "${restarts[$i]}" -gt 1 ] && prev="$run_dir/$rec_base.$((restarts[$i] - 1)).mcap"
      cut_recordings+=("$prev")
    fi
    launch "$i"
  done
  sleep 0.5 & wait $!  # the wait builtin returns at once on a trapped signal (a foreground sleep defers the trap)
done
if [ "$status" = 0 ]; then
  wait "$explorer_pid" || status=$?
fi
stop_all
wait "$tail_pid" 2>/dev/null || true
for f in "${cut_recordings[@]}"; do recover_recording "$f"; done
summary
exit "$status"
