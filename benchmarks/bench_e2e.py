"""End-to-end throughput and peak memory of `bathy run` on a Palmer survey, by workers and size.

Each configuration runs ``bathy run`` in a child process on ``data_synthetic/scenes/
palmer_survey.toml`` with its area's length scaled to the pulse count asked for, and records:
pulses per second end to end (wall, child start included) and of the chunk loop (simulate +
detect, on the workers) and of processing; pulses per CPU-second per stage (from the manifest:
the chunk stages' CPU seconds add up every worker's); CPU seconds (user + sys of the whole
process tree, ``os.wait4``); peak RSS of the largest process (``ru_maxrss``) and of the whole
tree (sum over the parent and its workers, sampled every 0.1 s with psutil); machine facts.

Run: .venv/bin/python benchmarks/bench_e2e.py [--pulses 150000] [--workers 1 2]
     [--memory 100000 300000 1000000] [--out FILE.md] [--log-dir DIR]
The scene flies without run-in (so small surveys are possible). The throughput runs keep the
scene's posteriors (their default budget); the memory series
turns them off. Prints the markdown (tables and the command); ``--out`` also writes it to a
file; ``--log-dir`` keeps each run's log (its chunks and blocks as they finish: a survey of
hours can be followed). ``benchmarks/RESULTS_e2e.md`` is a hand-kept record: paste a run's
tables into a section there rather than writing over it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
import tomllib
from pathlib import Path

import psutil

from pipeline.scene import parse_scene
from pipeline.simulate import survey
from pipeline.stress_support import to_toml

ROOT = Path(__file__).resolve().parents[1]
PALMER = ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml"
BATHY = Path(sys.executable).with_name("bathy")
#: stages of the chunk loop (run on the workers)
CHUNK_STAGES = ("survey", "trace", "receiver_waveform", "detect_waveform")


def palmer(pulses: int, posteriors: bool, chunk: int) -> dict:
    """The Palmer scene with its area's length set so the survey has about ``pulses``."""
    data = tomllib.loads(PALMER.read_text())
    if not posteriors:
        data["process"]["posterior_pulses_per_km2"] = 0.0
        data["process"]["posterior_min_pulses"] = 0
    data["run"] = {"chunk_pulses": chunk}
    # no run-in: its 2 × 150 m per line would set a floor of ~350 k pulses (the area's line
    # ends then lie in the scan circle's hole; coverage does not matter to a benchmark)
    data["flight"]["run_in_m"] = 0.0

    def count(length_m: float) -> int:
        data["flight"]["area_m"] = [0.0, 300.0, 0.0, length_m]
        s = parse_scene(data)
        return survey.plan_lines(s.flight, s.scanner).n_pulses_total

    length = 600.0
    for _ in range(4):  # pulses grow linearly with the length (plus the fixed run-in)
        n1, n2 = count(length), count(length + 100.0)
        length = max(10.0, length + (pulses - n1) * 100.0 / max(n2 - n1, 1))
    count(round(length, 1))
    return data


def run_one(scene: dict, workers: int, tmp: Path, name: str, log_dir: Path | None = None) -> dict:
    """``bathy run`` in a child; its figures from the manifest and the rusage.

    ``log_dir``: the run's log (its chunks and blocks as they are done) goes to
    ``log_dir/<name>.log`` instead of being silenced, to follow a long run.
    """
    path = tmp / f"{name}.toml"
    path.write_text(to_toml(scene))  # the stress suite's scene writer
    out = tmp / name
    cmd = [str(BATHY), "run", str(path), "--out", str(out), "--overwrite"]
    cmd += [] if log_dir is not None else ["--quiet"]
    cmd += ["--workers", str(workers)]
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    t0 = time.perf_counter()
    if log_dir is not None:
        Path(log_dir).mkdir(parents=True, exist_ok=True)
    log = None if log_dir is None else open(Path(log_dir) / f"{name}.log", "w")  # noqa: SIM115
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT if log else None)
    peak_tree = [0]
    done = threading.Event()

    def sample():  # the whole tree's RSS: parent + pool workers
        root = psutil.Process(proc.pid)
        while not done.is_set():
            try:
                procs = [root, *root.children(recursive=True)]
                peak_tree[0] = max(peak_tree[0], sum(p.memory_info().rss for p in procs))
            except psutil.Error:
                pass
            time.sleep(0.1)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    done.set()
    th.join()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if log is not None:
        log.close()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {proc.returncode}")
    man = json.loads((out / "manifest.json").read_text())
    ev = json.loads((out / "evaluation.json").read_text())
    stages = {s["stage"]: s for s in man["plan"] if s["runs"] and "wall_s" in s}
    stages.update(man.get("other_stages", {}))  # a blocked survey's block passes
    return {
        "name": name,
        # a blocked survey evaluates its sample: the survey's pulses are in its summary
        "pulses": ev.get("blocked", {}).get("survey_pulses", ev["pulses"]),
        "blocked": "blocked" in ev,
        "workers": man["execution"]["workers"],
        "wall_s": wall,
        "cpu_s": ru.ru_utime + ru.ru_stime,
        "sys_s": ru.ru_stime,
        "maxrss_mb": ru.ru_maxrss / 1024.0,
        "tree_rss_mb": peak_tree[0] / 2**20,
        "chunk_loop_wall_s": man["execution"]["map_wall_s"],
        "stages": stages,
        "posteriors": "posterior" in stages,
    }


def machine() -> list[str]:
    """CPU model, cores, load, library versions, commit."""
    model = "unknown"
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            model = line.split(":", 1)[1].strip()
            break
    import numba
    import numpy
    import open3d
    import scipy

    try:
        import distributed

        dask_v = distributed.__version__
    except ImportError:
        dask_v = "absent"
    commit = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip() or os.environ.get("BENCH_COMMIT", "unknown")  # a `git archive` copy
    mem = psutil.virtual_memory().total / 2**30
    return [
        f"- CPU: {model}, {os.cpu_count()} cores ({len(os.sched_getaffinity(0))} usable), "
        f"{mem:.0f} GiB RAM; load average at start {os.getloadavg()[0]:.2f}",
        f"- Python {platform.python_version()}, numpy {numpy.__version__}, scipy "
        f"{scipy.__version__}, numba {numba.__version__}, open3d {open3d.__version__}, "
        f"distributed {dask_v}; commit {commit}",
    ]


def rate(n: float, s: float) -> str:
    return f"{n / s / 1000:.1f} k" if s > 0 else "-"


def _throughput(runs: list[dict]) -> list[str]:
    lines = [
        "## Throughput by workers (Palmer 20°, 35 kHz, posteriors at the scene's default budget)",
        "",
        "Rates are pulses per wall second; *chunk loop* = simulate + detect on the workers;",
        "*+ process* adds the surface fit, refraction and classification (in the parent).",
        "",
        "| workers | pulses | end to end | chunk loop | chunk loop + process | CPU s (sys) "
        "| peak RSS largest / tree |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        proc_s = r["stages"].get("process", {}).get("wall_s", 0.0)
        lines.append(
            f"| {r['workers']} | {r['pulses']} | {rate(r['pulses'], r['wall_s'])} "
            f"({r['wall_s']:.0f} s) | {rate(r['pulses'], r['chunk_loop_wall_s'])} | "
            f"{rate(r['pulses'], r['chunk_loop_wall_s'] + proc_s)} | "
            f"{r['cpu_s']:.0f} ({r['sys_s']:.0f}) | "
            f"{r['maxrss_mb']:.0f} / {r['tree_rss_mb']:.0f} MB |"
        )
    lines += [
        "",
        "Per stage: pulses per CPU-second (wall seconds; for the chunk stages, summed over",
        "the workers).",
        "",
        "| stage | " + " | ".join(f"{r['workers']} worker(s)" for r in runs) + " |",
        "|---|" + "---|" * len(runs),
    ]
    names = [s for s in runs[0]["stages"]]
    for st in names:
        cells = []
        for r in runs:
            s = r["stages"].get(st)
            cells.append(
                f"{rate(r['pulses'], s['cpu_s'])} ({s['wall_s']:.1f} s)" if s is not None else "-"
            )
        lines.append(f"| {st} | " + " | ".join(cells) + " |")
    return lines


def report(runs: list[dict], mem_runs: list[dict], command: str) -> str:
    lines = [
        "# End-to-end benchmark (issue: survey-sized)",
        "",
        f"Command: `{command}`",
        "",
        *machine(),
        "- The machine's 2 cores were shared with other jobs during the runs: every rate is a",
        "  lower bound on what the code does on 2 idle cores, and the 2-worker speed-up is",
        "  understated (a worker waits for a core the other jobs hold).",
        "",
    ]
    if runs:
        lines += _throughput(runs)
    if mem_runs:
        lines += [
            "",
            "## Peak memory by survey size (posteriors off)",
            "",
            "| pulses | workers | blocked | wall s | end to end | peak RSS largest process | tree |"
            " per pulse over the smallest |",
            "|---|---|---|---|---|---|---|---|",
        ]
        base = mem_runs[0]
        for r in mem_runs:
            dn = r["pulses"] - base["pulses"]
            per = (r["maxrss_mb"] - base["maxrss_mb"]) * 2**20 / dn if dn else float("nan")
            lines.append(
                f"| {r['pulses']} | {r['workers']} | {'yes' if r['blocked'] else 'no'} | "
                f"{r['wall_s']:.0f} | "
                f"{rate(r['pulses'], r['wall_s'])} | {r['maxrss_mb']:.0f} MB | "
                f"{r['tree_rss_mb']:.0f} MB | {per:.0f} B |"
            )
        lines += [
            "",
            "The chunk loop holds at most 2 × workers chunks and spills each chunk's detections",
            "to disk. A survey of more than run.whole_pulses (or run.block_pulses) is",
            "processed in blocks (pipeline/survey_blocks.py, one block per worker at a time);",
            "a smaller one is held whole, its peak growing with the pulses (the last column).",
        ]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pulses", type=int, default=150_000, help="throughput runs' pulses")
    ap.add_argument(
        "--workers", type=int, nargs="*", default=[1, 2], help="throughput runs (none: skip)"
    )
    ap.add_argument("--memory", type=int, nargs="*", default=[100_000, 300_000, 1_000_000])
    ap.add_argument("--memory-workers", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=20_000, help="run.chunk_pulses")
    ap.add_argument("--out", default=None, help="also write the markdown to this file")
    ap.add_argument("--log-dir", default=None, help="write each run's log here (its progress)")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="run.KEY=VALUE",
        help="a run setting for the memory runs, e.g. run.block_pulses=500000 (repeatable)",
    )
    args = ap.parse_args()
    command = "python benchmarks/bench_e2e.py " + " ".join(sys.argv[1:])
    runs, mem_runs = [], []
    with tempfile.TemporaryDirectory(prefix="bench_e2e_") as tmp:
        scene = palmer(args.pulses, posteriors=True, chunk=args.chunk)
        for w in args.workers:
            runs.append(run_one(scene, w, Path(tmp), f"w{w}", args.log_dir))
            print(json.dumps({k: v for k, v in runs[-1].items() if k != "stages"}), flush=True)
        for n in args.memory:
            scene = palmer(n, posteriors=False, chunk=args.chunk)
            for kv in args.set:
                key, value = kv.split("=", 1)
                section, name = key.split(".", 1)
                scene.setdefault(section, {})[name] = float(value) if "." in value else int(value)
            mem_runs.append(run_one(scene, args.memory_workers, Path(tmp), f"m{n}", args.log_dir))
            print(json.dumps({k: v for k, v in mem_runs[-1].items() if k != "stages"}), flush=True)
            for st, v in mem_runs[-1]["stages"].items():  # wall, CPU (all workers), own peak
                peak = v.get("peak_rss_mb")
                print(
                    f"  {st:20s} wall {v['wall_s']:8.1f} s  cpu {v['cpu_s']:8.1f} s  "
                    f"peak {'-' if peak is None else f'{peak:.0f} MiB'}",
                    flush=True,
                )
    text = report(runs, mem_runs, command)
    if args.out is not None:
        Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
