"""Run a benchmark and publish its figures as a results file in ``docs/results/``.

    python benchmarks/publish.py peers            # bench_peers.py -> docs/results/peers.json
    python benchmarks/publish.py faults           # bench_faults.py -> docs/results/faults.json

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
                    f"{log} {label} error [m]".replace("  ", " ")]
    runners = list(raw["logs"][logs[0]]["cpu_ms_per_scan"])
    rows = []
    for runner in runners:
        row = [shown.get(runner, runner)]
        for log in logs:
            result = raw["logs"][log]
            ms = result["cpu_ms_per_scan"][runner]
            ratio = ms / result["cpu_ms_per_scan"][peer] if peer in result["cpu_ms_per_scan"] \
                else float("nan")
            errors = result["errors"].get(runner, {})
            error = next(iter(errors.values()), {}).get("translation_m", float("nan"))
            row += [f"{ms:.3f}", f"{ratio:.2f}", f"{error:.4f}"]
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


#: name -> (benchmark module, its arguments, what it measures, tables from its JSON)
PUBLISHED: dict[str, tuple[str, list[str], str, Callable[[Any], dict[str, Any]]]] = {
    "peers": ("bench_peers", [], "lidar_odometry, slam and icp beside KISS-ICP on the same "
              "scans (first 2,000 of ACES and Intel), interleaved scan by scan, CPU time per "
              "scan; KISS-ICP's Python API on z = 0 points, voxel 0.25 m, deskew off, 1 "
              "thread; relation errors on ACES's Kümmerle relations and Intel's 1 s relations "
              "of the SLAM-corrected log", peers_tables),
    "faults": ("bench_faults", [], "every fault x lidar_odometry, slam, pc_fusion, icp x the "
               "three paper groups and the first scans of ACES: runs whose worst step is at "
               "most 0.3 m beyond the clean run's and whose final error is at most 2x the "
               "clean one + 0.1 m", faults_tables),
}


def publish(name: str) -> Path:
    module, argv, what, tables = PUBLISHED[name]
    version = package_version()
    raw = _run(module, argv)
    out = RESULTS / f"{name}.json"
    out.write_text(json.dumps({
        "what": what,
        "command": f"python benchmarks/publish.py {name}",
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
    args = parser.parse_args(argv)
    for name in args.names:
        print(f"wrote {publish(name)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
