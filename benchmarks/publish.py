"""Run a benchmark and publish its figures as a results file in ``docs/results/``.

    python benchmarks/publish.py peers        # bench_peers.py -> docs/results/peers.json
    python benchmarks/publish.py faults       # bench_faults.py -> docs/results/faults.json
    python benchmarks/publish.py vector       # bench_vector_env.py -> docs/results/vector.json
    python benchmarks/publish.py cold_start   # bench_cold_start.py -> docs/results/cold_start.json
    python benchmarks/publish.py vector --bench-args="--seconds 0.2"  # recorded in the file

The benchmark runs in this process, so the code version the results file records
(:func:`estimators.leaderboard.records.package_version`) is the code that made the figures;
``tests/test_docs.py`` fails when the code changes after it. Each results file names the
command, the machine and the tables the README and the docs pages quote (``docs/hooks.py``
writes them into the pages below their ``<!-- results-table: FILE TABLE -->`` markers).
"""

from __future__ import annotations

import argparse
import json
import platform
import shlex
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
RESULTS = HERE.parent / "docs" / "results"
sys.path.insert(0, str(HERE))

from estimators.leaderboard.records import package_version  # noqa: E402


def _machine() -> str:
    import os

    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"


def _run(module: str, argv: list[str]) -> Any:
    """Run ``benchmarks/<module>.py`` with ``argv`` plus ``--json`` and read what it wrote
    (its exit status may say that targets were missed; the results file records which)."""
    bench = __import__(module)
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "raw.json"
        bench.main([*argv, "--json", str(out)])
        if not out.is_file():
            raise SystemExit(f"{module} wrote no results")
        return json.loads(out.read_text())


def peers_tables(raw: dict[str, Any]) -> dict[str, Any]:
    """One row per runner: CPU ms per scan, its ratio to KISS-ICP, and the relation error."""
    logs = list(raw["logs"])
    peer = raw["peer"]
    shown = {peer: "KISS-ICP"}  # the peer as its authors name it
    columns = ["estimator"]
    for log in logs:
        label = next(iter(raw["logs"][log]["errors"].get(peer, {"": 0})), "")
        columns += [f"{log} CPU [ms/scan]", f"{log} × KISS-ICP CPU",
                    f"{log} kernels × KISS-ICP CPU", f"{log} {label} error [m]".replace("  ", " ")]
    runners = list(raw["logs"][logs[0]]["cpu_ms_per_scan"])
    rows = []
    for runner in runners:
        row = [shown.get(runner, runner)]
        for log in logs:
            result = raw["logs"][log]
            ms = result["cpu_ms_per_scan"][runner]
            ratio = ms / result["cpu_ms_per_scan"][peer] if peer in result["cpu_ms_per_scan"] \
                else float("nan")
            inside = result.get("kernel_ms_per_scan", {}).get(runner)
            kernels = "" if inside is None or peer not in result["cpu_ms_per_scan"] else (
                f"{inside / result['cpu_ms_per_scan'][peer]:.2f}")
            errors = result["errors"].get(runner, {})
            error = next(iter(errors.values()), {}).get("translation_m", float("nan"))
            row += [f"{ms:.3f}", f"{ratio:.2f}", kernels, f"{error:.4f}"]
        rows.append(row)
    return {"peers": {"columns": columns, "rows": rows}}


def faults_tables(raw: list[dict[str, Any]]) -> dict[str, Any]:
    """Runs meeting both targets, per fault and estimator, of the drives tried."""
    faults = list(dict.fromkeys(run["fault"] for run in raw))
    names = list(dict.fromkeys(run["estimator"] for run in raw))
    rows = []
    for fault in faults:
        row = [fault]
        for name in names:
            runs = [run for run in raw if run["fault"] == fault and run["estimator"] == name]
            row.append(f"{sum(bool(run['pass']) for run in runs)} / {len(runs)}")
        rows.append(row)
    return {"passes": {"columns": ["fault", *names], "rows": rows}}


def _met(target: dict[str, Any]) -> str:
    return "yes" if target["met"] else "no"


def vector_tables(raw: dict[str, Any]) -> dict[str, Any]:
    """Steps/s of the batched env and of SyncVectorEnv per N with their ratio, and each target
    with the figure measured for it."""
    speed = {"columns": ["N", "batched [steps/s]", "SyncVectorEnv [steps/s]",
                         "batched / SyncVectorEnv"],
             "rows": [[n, f"{figures['batched']:,.0f}", f"{figures['sync']:,.0f}",
                       f"{figures['ratio']:.2f}"] for n, figures in raw["sizes"].items()]}
    single = raw["single"]
    rows = []
    for target in raw["targets"]:
        shown = f"{target['value']:.2f}"  # every target is a ratio
        if "single env" in target["target"]:
            shown += f" ({single['batched']:,.0f} / {single['single']:,.0f} steps/s)"
        rows.append([target["target"], str(target["n"]), shown, _met(target)])
    return {"speed": speed,
            "targets": {"columns": ["target", "measured at N", "measured", "met"], "rows": rows}}


#: The cold-start probe's phases as the table names them.
SHOWN_PHASES = {"first step": "import to first step, in all"}


def cold_start_tables(raw: dict[str, Any]) -> dict[str, Any]:
    """Wall and CPU seconds of each phase of a fresh process (and against an empty numba cache,
    with the ratios, when it ran), and each target with the figure measured for it."""
    cold = raw["empty_cache"]
    columns = ["phase", "wall [s]", "CPU [s]"]
    if cold is not None:
        columns += ["empty cache wall [s]", "empty cache CPU [s]", "empty / this cache wall",
                    "empty / this cache CPU"]
    rows = []
    for phase, (wall, cpu) in raw["cached"]["phases"].items():
        row = [SHOWN_PHASES.get(phase, phase), f"{wall:.2f}", f"{cpu:.2f}"]
        if cold is not None:
            cold_wall, cold_cpu = cold["phases"][phase]
            ratio_wall, ratio_cpu = raw["ratios"][phase]
            row += [f"{cold_wall:.2f}", f"{cold_cpu:.2f}", f"{ratio_wall:.1f}",
                    f"{ratio_cpu:.1f}"]
        rows.append(row)
    compiled = ["numba kernels compiled", str(raw["cached"]["compiled"]), ""]
    if cold is not None:
        compiled += [str(cold["compiled"]), "", "", ""]
    rows.append(compiled)
    targets = [[target["target"], f"{target['value']:.2f}" if isinstance(target["value"], float)
                else str(target["value"]), _met(target)] for target in raw["targets"]]
    return {"phases": {"columns": columns, "rows": rows},
            "targets": {"columns": ["target", "measured", "met"], "rows": targets}}


#: name -> (benchmark module, its arguments, what it measures, tables from its JSON)
PUBLISHED: dict[str, tuple[str, list[str], str, Callable[[Any], dict[str, Any]]]] = {
    "peers": ("bench_peers", ["--kernels"], "lidar_odometry, slam and icp beside KISS-ICP on "
              "the same scans (first 2,000 of ACES and Intel), interleaved scan by scan, CPU "
              "time per scan, and the CPU of our compiled kernels alone (a second, profiled "
              "run) over KISS-ICP's whole; KISS-ICP's Python API on z = 0 points, voxel "
              "0.25 m, deskew off, 1 thread; relation errors on ACES's Kümmerle relations and "
              "Intel's 1 s relations of the SLAM-corrected log", peers_tables),
    "faults": ("bench_faults", [], "every fault x lidar_odometry, slam, pc_fusion, icp x the "
               "three paper groups and 600 scans of ACES from its first truth, of ACES from scan "
               "6000 and of Intel from scan 3000: runs whose worst step is at "
               "most 0.3 m beyond the clean run's and whose final error is at most 2x the "
               "clean one + 0.1 m; after over 3 s blind in a row, runs whose step onto the "
               "first scan with returns is at most 0.3 m beyond the clean run's worst, that "
               "flag the stretch, and that meet the final bound or, where that scan does not "
               "cover the place (under half its points within 0.2 m of the last scan's before "
               "the stretch), report it lost", faults_tables),
    "vector": ("bench_vector_env", ["--sizes", "1", "32", "256"], "env steps per CPU second "
               "of the batched DualLidar-v0 (make_vec, vector_entry_point) and of SyncVectorEnv "
               "over N single envs, default config, random actions, autoresets included, timed "
               "in alternating 50 ms slices of one process; the single env "
               "(gym.make) against the batched env at N = 1 the same way", vector_tables),
    "cold_start": ("bench_cold_start", ["--empty-cache"], "a fresh Python process's first "
                   "import lidar_env + gym.make + reset + step, then make_vec(32) + reset + "
                   "step, wall and CPU seconds timed inside it, with this clone's numba cache "
                   "(as after scripts/setup.sh) and with an empty one; numba compile events "
                   "counted", cold_start_tables),
}


def publish(name: str, bench_args: list[str] | None = None) -> Path:
    """Run benchmark ``name`` (with ``bench_args`` in place of its published arguments, if
    given) and write its results file; returns its path."""
    module, argv, what, tables = PUBLISHED[name]
    version = package_version()
    raw = _run(module, argv if bench_args is None else bench_args)
    command = f"python benchmarks/publish.py {name}"
    if bench_args is not None:
        command += f" --bench-args={shlex.quote(shlex.join(bench_args))}"
    out = RESULTS / f"{name}.json"
    out.write_text(json.dumps({
        "what": what,
        "command": command,
        "hardware": raw.get("machine", _machine()) if isinstance(raw, dict) else _machine(),
        "python": f"CPython {platform.python_version()}",
        "source_version": version,
        "files": {},
        "tables": tables(raw),
        "raw": raw,
    }, indent=1, ensure_ascii=False) + "\n")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("names", nargs="+", choices=sorted(PUBLISHED),
                        help="the results to regenerate")
    parser.add_argument("--bench-args", metavar="ARGS", default=None,
                        help="the benchmark's arguments in place of the published ones (one "
                        "name only; the results file records them in its command)")
    args = parser.parse_args(argv)
    if args.bench_args is not None and len(args.names) != 1:
        parser.error(f"--bench-args: expected one name, got {len(args.names)}")
    bench_args = None if args.bench_args is None else shlex.split(args.bench_args)
    for name in args.names:
        print(f"wrote {publish(name, bench_args)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
