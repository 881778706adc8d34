"""Long runs (soak): ``scripts/bench.sh soak [--touches-2d N] [--touches-3d N] [--json F]``.

Runs ``scripts/explore.sh`` (recorder on, as always) for a long 2D run and a long
3D run, one after the other, and samples while each runs, every ``--interval``
seconds of wall time:

* the resident memory (``VmRSS`` of ``/proc/<pid>/status``, MB) of every node
  process of the run (found by its command line: ``bin/<node> --ros-args`` with
  this run's ``params/`` files; a restarted node is followed to its new pid);
* the size of the run's recordings (``run.mcap`` and any ``run.N.mcap``, MB);
* how many touches the explorer has logged (``touch k/N`` lines of logs/explorer.log).

After the run the per-decision time comes from report.json (``decision_ms`` of
each touch: the planner's answer time, wall clock). The curves (one value per
touch, :func:`tactile_bringup.soak_analysis.per_touch`) are printed every 10
touches, each is fitted with a line after the warm-up and judged ``bounded``,
``linear`` or ``superlinear`` (:func:`tactile_bringup.soak_analysis.judge_growth`);
the figure goes to soak.png in the output folder and everything to ``--json``.
Exit status 1 when a run did not complete its budget or a node's memory grew
faster than linearly.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

import numpy as np

from .cli_common import Parser, finite_float, integer
from .soak_analysis import format_table, judge_growth, per_touch, table_every

ROOT = Path(os.environ.get("TACTILE_ROOT") or Path(__file__).resolve().parents[3])  # holds scripts/explore.sh
NODES = ("recorder", "sim_rig", "tactile_sensor", "gpis_estimator", "soc_planner", "viz", "arm_commander",
         "explorer")
_TOUCH_LINE = re.compile(r"touch +\d+/")
_STAMP = re.compile(r"^\[\w+\] \[(\d+\.\d+)\]")  # rcutils' log line: [LEVEL] [wall s] [node]: ...


def find_node_pids(run_dir: Path, names=NODES, proc: Path = Path("/proc")) -> dict[str, int]:
    """The live process of each node of the run in ``run_dir`` (name → pid; newest pid wins).

    A node process is one whose command line has an argument ending in ``bin/<name>``
    followed by ``--ros-args`` and a parameter file under ``<run_dir>/params/``.
    """
    marker = f"{Path(run_dir)}/params/"
    found: dict[str, int] = {}
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue  # gone, or not ours
        args = [a.decode(errors="replace") for a in argv if a]
        if "--ros-args" not in args or not any(marker in a for a in args):
            continue
        head = args[:args.index("--ros-args")]
        for name in names:
            if any(a == name or a.endswith("/" + name) for a in head):
                pid = int(entry.name)
                found[name] = max(pid, found.get(name, 0))
    return found


def rss_mb(pid: int, proc: Path = Path("/proc")) -> float:
    """Resident memory of ``pid`` in MB (``VmRSS``), NaN if the process is gone."""
    try:
        for line in (proc / str(pid) / "status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0  # kB → MB
    except (OSError, ValueError, IndexError):
        pass
    return float("nan")


def recording_mb(run_dir: Path) -> float:
    """Size of the run's recordings (run.mcap and run.N.mcap) in MB."""
    total = 0
    for p in Path(run_dir).glob("run*.mcap"):
        try:
            total += p.stat().st_size
        except OSError:
            pass
    return total / 1e6


def touches_done(run_dir: Path) -> int:
    """Touches the explorer has logged so far (``touch k/N`` lines of logs/explorer.log)."""
    try:
        return len(_TOUCH_LINE.findall((Path(run_dir) / "logs" / "explorer.log").read_text(errors="replace")))
    except OSError:
        return 0


def _stamps(path: Path, text: str) -> np.ndarray:
    """Wall-clock stamps (s) of the log lines of ``path`` that contain ``text``."""
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError:
        return np.zeros(0)
    return np.array([float(m.group(1)) for line in lines if text in line and (m := _STAMP.match(line))])


def held_contacts(run_dir: Path, outcomes: list) -> list[int]:
    """Contacts the estimator holds after each touch: contacts so far minus those it rejected as
    duplicates (within ``duplicate_distance_m`` of an earlier one), from the explorer's and the
    estimator's logs (one wall clock). A restarted estimator's log is appended to the same file."""
    logs = Path(run_dir) / "logs"
    touch_t = _stamps(logs / "explorer.log", "touch ")
    touch_t = touch_t[:len(outcomes)]
    dup_t = np.sort(_stamps(logs / "gpis_estimator.log", "duplicate"))
    contacts = np.cumsum([o == "contact" for o in outcomes[:len(touch_t)]])
    rejected = np.searchsorted(dup_t, touch_t, side="right")
    return [int(c - r) for c, r in zip(contacts, rejected)]


def sample(run_dir: Path, t0: float) -> dict:
    """One sample of the run: wall time since ``t0`` (s), touches done, MCAP MB, RSS MB per node."""
    pids = find_node_pids(run_dir)
    return {"t_s": round(time.monotonic() - t0, 2), "touches": touches_done(run_dir),
            "mcap_mb": recording_mb(run_dir), "rss_mb": {n: rss_mb(p) for n, p in pids.items()}}


def stop_leftovers(run_dir: Path, log=sys.stderr, timeout_s: float = 15.0) -> list[str]:
    """Nodes of the run still alive after explore.sh ended: SIGINT (then SIGKILL) each; their names."""
    left = find_node_pids(run_dir)
    if left:
        print(f"soak: explore.sh left {sorted(left)} running; stopping them", file=log, flush=True)
    for name, pid in sorted(left.items(), key=lambda kv: kv[0] == "recorder"):  # the recorder last
        try:
            os.kill(pid, signal.SIGINT)
        except ProcessLookupError:
            continue
        end = time.monotonic() + timeout_s
        while time.monotonic() < end and Path(f"/proc/{pid}").exists():
            time.sleep(0.1)  # waiting on the process's exit
        if Path(f"/proc/{pid}").exists():
            os.kill(pid, signal.SIGKILL)
    return sorted(left)


def run_soak(mode: str, touches: int, out: Path, *, seed: int = 1, interval_s: float = 1.0,
             max_minutes: Optional[float] = None, explore_args: tuple[str, ...] = (),
             env: Optional[dict] = None, log=sys.stderr) -> dict:
    """One long graph run of ``touches`` touches in ``mode``, sampled every ``interval_s`` (wall s).

    ``max_minutes`` stops the run (SIGINT: the explorer writes the report so far) when it is
    exceeded. Returns the raw samples, the report's per-touch decision times and outcomes,
    the run's exit status and wall time.
    """
    out = Path(out)
    cmd = ["bash", str(ROOT / "scripts" / "explore.sh"), "--mode", mode, "--touches", str(touches),
           "--seed", str(seed), "--out", str(out), *explore_args]
    out.parent.mkdir(parents=True, exist_ok=True)
    console = open(f"{out}.log", "w")
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=console, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            env=env, start_new_session=True)
    samples, stopped, last_print = [], "", 0
    try:
        while proc.poll() is None:
            s = sample(out, t0)
            samples.append(s)
            if s["touches"] >= last_print + 10:
                last_print = s["touches"] - s["touches"] % 10
                print(f"soak {mode}: {s['touches']}/{touches} touches after {s['t_s'] / 60:.1f} min, "
                      f"MCAP {s['mcap_mb']:.1f} MB", file=log, flush=True)
            if max_minutes is not None and not stopped and s["t_s"] > 60 * max_minutes:
                stopped = f"stopped after {max_minutes:g} min (--max-minutes)"
                print(f"soak {mode}: {stopped}", file=log, flush=True)
                os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(timeout=interval_s)  # the sampling period (also ends at once when the run does)
            except subprocess.TimeoutExpired:
                pass
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
            proc.wait(timeout=60)
        console.close()
    left = stop_leftovers(out, log)
    report_path = out / "report.json"
    report = json.loads(report_path.read_text()) if report_path.exists() else {"touches": [], "summary": {}}
    return {"mode": mode, "budget": touches, "out": str(out), "command": " ".join(cmd), "status": proc.returncode,
            "wall_s": round(time.monotonic() - t0, 1), "stopped": stopped, "samples": samples,
            "decision_ms": [t.get("decision_ms") for t in report["touches"]],
            "outcomes": [t.get("outcome") for t in report["touches"]], "left_running": left,
            "held_contacts": held_contacts(out, [t.get("outcome") for t in report["touches"]]),
            "stopped_because": report.get("summary", {}).get("stopped_because", "no report")}


def analyse(run: dict, *, warmup: Optional[int] = None, rss_bound_mb: float = 20.0,
            mcap_bound_mb: float = 0.5, decision_bound_ms: float = 50.0) -> dict:
    """The per-touch curves of one :func:`run_soak` result and their growth verdicts.

    Touches are those the report holds (else those the explorer logged); ``warmup``
    defaults to max(4, a tenth of them). Bounds are the rise of the fitted line still
    called bounded: RSS per node (MB), MCAP (MB), decision time (ms). The fits end at
    the second-to-last touch when the run completed: the last touch's interval holds
    the end of the run (the explorer writes the report and draws progress.png).
    """
    samples = run["samples"]
    n = len(run["decision_ms"]) or max((s["touches"] for s in samples), default=0)
    if n < 1:
        raise ValueError(f"{run['mode']} run logged no touch (see {run['out']}.log)")
    warmup = warmup if warmup is not None else max(4, n // 10)
    k = [s["touches"] for s in samples]
    curves: dict[str, np.ndarray] = {}
    for node in NODES:
        curves[f"{node}_mb"] = per_touch(k, [s["rss_mb"].get(node, np.nan) for s in samples], n)
    curves["mcap_mb"] = per_touch(k, [s["mcap_mb"] for s in samples], n)
    dec = np.array([np.nan if d is None else d for d in run["decision_ms"]] + [np.nan] * (n - len(run["decision_ms"])),
                   dtype=float)
    curves["decision_ms"] = dec
    held = run.get("held_contacts") or []
    curves["gp_contacts"] = np.array(held + [np.nan] * (n - len(held)), dtype=float)[:n]
    contacts = np.cumsum([o == "contact" for o in run["outcomes"]]) if run["outcomes"] else np.zeros(0)
    verdicts = {}
    last = n - 1 if run["stopped_because"] == "touch budget" and n > 1 else n
    if last - warmup + 1 >= 3:
        for name, c in curves.items():
            if name == "gp_contacts":
                continue  # a count, shown beside the memory it explains
            bound = mcap_bound_mb if name == "mcap_mb" else decision_bound_ms if name == "decision_ms" \
                else rss_bound_mb
            try:
                verdicts[name] = judge_growth(c, warmup=warmup, bound=bound, last=last).as_dict()
            except ValueError as err:  # e.g. a node never found: no samples
                verdicts[name] = {"verdict": "no data", "reason": str(err)}
    return {"touches": n, "warmup": warmup, "last_judged": last, "contacts": [int(c) for c in contacts],
            "curves": {k_: [None if not np.isfinite(x) else round(float(x), 3) for x in v] for k_, v in curves.items()},
            "every_10": table_every(curves, 10), "growth": verdicts}


def plot_soak(results: list[dict], path: Path) -> Path:
    """soak.png: per mode, RSS of each node, MCAP size and decision time against the touch."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(results), 3, figsize=(15, 4.2 * len(results)), squeeze=False)
    for row, res in zip(axes, results):
        a = res["analysis"]
        x = np.arange(1, a["touches"] + 1)
        curves = {k: np.array([np.nan if v is None else v for v in c], dtype=float) for k, c in a["curves"].items()}
        for node in NODES:
            row[0].plot(x, curves[f"{node}_mb"], label=node)
        row[0].set(title=f"{res['mode']}: resident memory per node", xlabel="touch", ylabel="RSS (MB)")
        row[0].legend(fontsize=7, ncol=2, loc="lower right")
        if np.isfinite(curves["gp_contacts"]).any():  # what the estimator's state grows with
            twin = row[0].twinx()
            twin.plot(x, curves["gp_contacts"], "k:", label="contacts held by the GP")
            twin.set_ylabel("contacts held by the GP (dotted)")
        for ax, name, unit in ((row[1], "mcap_mb", "MCAP size (MB)"), (row[2], "decision_ms", "decision time (ms)")):
            ax.plot(x, curves[name], ".", ms=3)
            g = a["growth"].get(name, {})
            if "slope" in g:
                xs = np.array([g["first"], g["last"]])
                ax.plot(xs, g["slope"] * xs + g["intercept"], "r-",
                        label=f"fit from touch {g['first']}: {g['slope']:.3g}/touch ({g['verdict']})")
                ax.legend(fontsize=8)
            ax.set(title=f"{res['mode']}: {unit}", xlabel="touch", ylabel=unit)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def print_result(res: dict, file=sys.stdout) -> None:
    """The curves every 10 touches and the growth verdict of each."""
    a = res["analysis"]
    print(f"\n== {res['mode']}: {a['touches']}/{res['budget']} touches ({res['stopped_because']}{', ' + res['stopped'] if res['stopped'] else ''}), "
          f"{a['contacts'][-1] if a['contacts'] else 0} contacts, {res['wall_s'] / 60:.1f} min wall, exit {res['status']}",
          file=file)
    print(f"   command: {res['command']}", file=file)
    short = [{("touch" if k == "touch" else k.replace("_mb", "").replace("tactile_", "").replace("gpis_", "")
               .replace("arm_", "").replace("gp_contacts", "gp_held")): v for k, v in r.items()} for r in a["every_10"]]
    print(format_table(short), file=file)
    if res.get("left_running"):
        print(f"   explore.sh left running (stopped by the soak): {', '.join(res['left_running'])}", file=file)
    print(f"   growth, touches {a['warmup']}-{a['last_judged']} (line fit: slope per touch, its rise, peak rise; "
          f"verdict):", file=file)
    for name, g in a["growth"].items():
        if "slope" in g:
            print(f"   {name:22s} {g['slope']:+9.4f}/touch  rise {g['growth']:+8.2f}  peak {g['peak_rise']:+8.2f}  "
                  f"r² {g['r2']:.2f}  {g['verdict']}", file=file)
        else:
            print(f"   {name:22s} {g['verdict']}: {g.get('reason', '')}", file=file)


def main(argv: Optional[list[str]] = None) -> int:
    ap = Parser(prog="bench.sh soak", description="Long 2D and 3D graph runs (recorder on), sampled for the resident "
                "memory of each node, the MCAP size and the decision time per touch; prints the curves every 10 "
                "touches with a line fit and a verdict each, writes soak.png (docs/benchmarks.md, 'Long runs').")
    ap.add_argument("--touches-2d", type=integer, default=200, help="touches of the 2D run (0: no 2D run; default 200)")
    ap.add_argument("--touches-3d", type=integer, default=100, help="touches of the 3D run (0: no 3D run; default 100)")
    ap.add_argument("--seed", type=integer, default=1, help="seed of both runs (default 1)")
    ap.add_argument("--out", default=None, help="folder of the runs and soak.png (default: a new folder in $TMPDIR)")
    ap.add_argument("--json", default=None, metavar="FILE", help="also write the samples, curves and verdicts here")
    ap.add_argument("--interval", type=finite_float, default=1.0, help="sampling period, wall s (default 1)")
    ap.add_argument("--max-minutes", type=finite_float, default=None,
                    help="stop a run (SIGINT, the report so far is kept) after this many wall minutes")
    ap.add_argument("--from-json", default=None, metavar="FILE",
                    help="analyse the samples of an earlier soak's --json again (no run); soak.png beside FILE")
    ap.add_argument("--rss-bound-mb", type=finite_float, default=20.0,
                    help="rise of a node's RSS after the warm-up still called bounded (default 20 MB)")
    args = ap.parse_args(argv)
    if args.touches_2d < 0 or args.touches_3d < 0 or args.touches_2d + args.touches_3d == 0:
        ap.error("--touches-2d and --touches-3d must be >= 0 and not both 0")
    if args.interval <= 0:
        ap.error(f"--interval {args.interval:g}: must be > 0")
    if args.seed < 0:
        ap.error(f"--seed {args.seed}: must be >= 0")
    if args.max_minutes is not None and args.max_minutes <= 0:
        ap.error(f"--max-minutes {args.max_minutes:g}: must be > 0")
    if args.json and not Path(args.json).resolve().parent.is_dir():
        ap.error(f"--json {args.json}: its folder does not exist")
    if args.from_json:
        try:
            earlier = json.loads(Path(args.from_json).read_text())
        except (OSError, ValueError) as exc:
            ap.error(f"--from-json {args.from_json}: {exc}")
        out = Path(args.out) if args.out else Path(args.from_json).resolve().parent
        runs = iter(earlier)
    else:
        out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="tactile-soak."))
        if any((out / m).exists() for m in ("2d", "3d")):
            ap.error(f"--out {out}: already holds a soak run; choose another folder")
        runs = (run_soak(mode, n, out / mode, seed=args.seed, interval_s=args.interval, max_minutes=args.max_minutes)
                for mode, n in (("2d", args.touches_2d), ("3d", args.touches_3d)) if n > 0)
    results = []
    for res in runs:
        res.pop("analysis", None)
        if "held_contacts" not in res:  # a soak of before this count: from the run's logs
            res["held_contacts"] = held_contacts(Path(res["out"]), res["outcomes"])
        try:
            res["analysis"] = analyse(res, rss_bound_mb=args.rss_bound_mb)
        except ValueError as err:  # no touch at all: say so, keep the samples, go on
            print(f"bench.sh soak: {err}", file=sys.stderr)
            results.append(res)
            continue
        print_result(res)
        results.append(res)
    analysed = [r for r in results if "analysis" in r]
    if analysed:
        png = plot_soak(analysed, out / "soak.png")
        print(f"\nfigure: {png}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
        print(f"figures: {args.json}")
    ok = all(r["stopped_because"] == "touch budget" and r["status"] == 0 and not r.get("left_running") for r in results)
    leak = [f"{r['mode']} {name}" for r in analysed for name, g in r["analysis"]["growth"].items()
            if name.endswith("_mb") and name != "mcap_mb" and g.get("verdict") == "superlinear"]
    if leak:
        print(f"bench.sh soak: memory grew faster than linearly: {', '.join(leak)}", file=sys.stderr)
    return 0 if ok and not leak else 1


if __name__ == "__main__":
    sys.exit(main())
