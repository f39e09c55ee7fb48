"""Long blind stretches anywhere on a drive: stretches x offsets x seeds x drives x estimators,
each run judged by the fault matrix's rule for a stretch longer than 3 s (issue 43).

    python benchmarks/bench_blind_stretches.py                        # all four (~15 min)
    python benchmarks/bench_blind_stretches.py --estimators lidar_odometry --seeds 0
    python benchmarks/bench_blind_stretches.py --stretches 100 --offsets 40 --json out.json

The fault matrix (``benchmarks/bench_faults.py``) tries one long stretch (``blind_100``: 100
scans, 10 s, from scan 60) on seed 0; this sweep moves it along the drive (``--offsets``, the
index of the first blind scan), varies its length (``--stretches``, scans) and the drive's
seed (``--seeds``) on the paper groups. Each drive is recorded once and each estimator's clean
run made once; every stretch is applied to the recording
(:class:`lidar_env.faults.Blind`). A run passes by ``bench_faults.verdict``: its step onto
the first scan with returns at most 0.3 m beyond the clean run's worst, ``health`` counting
the stretch, and the end-point bound (2 x clean final + 0.1 m) met, or, where that scan does
not cover the place (``covered`` under 0.5), the scan reported lost (``lost``: the estimator's
``health.lost_scans``). A run failing the bound without reporting a scan lost is a silent
wrong answer (``silent``). Per run: ``final`` and ``clean`` [m], ``jump+`` [m] (the return
step's error beyond the clean run's worst), ``covered``, ``lost``, pass; per estimator, the
passes, the end-point bounds met and the silent failures; CPU seconds by
``time.process_time``.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

from bench_faults import (
    ESTIMATORS,
    GROUPS,
    FaultedRun,
    faulted_run,
    final_bound,
    record_drive,
    run,
    score,
    start_of,
    verdict,
)

import estimators
from estimators.datasets.recording import Recording
from lidar_env.faults import Blind


def blind_run(name: str, recording: Recording, stretch: int, offset: int) -> FaultedRun:
    """``name`` on ``recording`` blind for ``stretch`` scans from scan ``offset``, scored as
    the fault matrix scores its faulted runs (against the truth, which the simulated drives
    carry per scan)."""
    return faulted_run(name, recording, [Blind(every=10_000, stretch=stretch, offset=offset)])


def sweep(names: list[str], groups: list[str], seeds: list[int], stretches: list[int],
          offsets: list[int]) -> list[dict]:
    """One result row per run (printed as it comes)."""
    results: list[dict] = []
    for group in groups:
        for seed in seeds:
            recording = record_drive(group, seed)
            for name in names:
                clean, _, _ = run(name, recording, start_of(recording.truth))
                clean_jump, clean_final = score(clean, recording.truth, recording.truth)
                for stretch in stretches:
                    for offset in offsets:
                        faulted = blind_run(name, recording, stretch, offset)
                        ok = verdict(faulted, clean_jump, clean_final)
                        bound = faulted.final <= final_bound(clean_final)
                        lost = int(faulted.health.get("lost_scans", 0))
                        jump_plus = (None if faulted.return_jump is None
                                     else faulted.return_jump - clean_jump)
                        results.append({
                            "drive": group, "seed": seed, "estimator": name,
                            "stretch": stretch, "offset": offset, "final": faulted.final,
                            "clean_final": clean_final, "return_jump_plus": jump_plus,
                            "covered": faulted.covered, "lost_scans": lost,
                            "bound": bool(bound), "silent": bool(not bound and not lost),
                            "pass": bool(ok), "cpu_s": faulted.seconds,
                            "health": faulted.health})
                        jump_text = "  n/a" if jump_plus is None else f"{jump_plus:6.3f}"
                        covered = "n/a " if faulted.covered is None else f"{faulted.covered:4.2f}"
                        silent = "  silent" if results[-1]["silent"] else ""
                        print(f"{group:26s} s{seed} {name:15s} blind{stretch}@{offset:<4d} "
                              f"final {faulted.final:7.3f} clean {clean_final:6.3f} jump+ "
                              f"{jump_text} covered {covered} lost {lost}  "
                              f"{'pass' if ok else 'FAIL'}{silent}  {faulted.seconds:5.1f} s",
                              flush=True)
    return results


def summary(results: list[dict], names: list[str]) -> list[str]:
    """Per estimator: passes, end-point bounds met and silent failures out of its runs."""
    lines = []
    for name in names:
        rows = [r for r in results if r["estimator"] == name]
        lines.append(f"{name:15s} pass {sum(r['pass'] for r in rows):3d} / {len(rows)}  "
                     f"bound met {sum(r['bound'] for r in rows):3d}  "
                     f"silent {sum(r['silent'] for r in rows):3d}  "
                     f"cpu {sum(r['cpu_s'] for r in rows):6.1f} s")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--estimators", nargs="+", default=list(ESTIMATORS),
                        choices=estimators.names())
    parser.add_argument("--groups", nargs="+", default=list(GROUPS), choices=GROUPS)
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    parser.add_argument("--stretches", nargs="+", type=int, default=[60, 100],
                        help="blind scans in a row")
    parser.add_argument("--offsets", nargs="+", type=int, default=[40, 80, 120, 160],
                        help="index of the first blind scan")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args(argv)
    for option, values in (("--stretches", args.stretches), ("--offsets", args.offsets)):
        if min(values) < 1:
            parser.error(f"{option}: expected scan counts >= 1, got {min(values)}")
    print(f"machine: {platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}")
    results = sweep(args.estimators, args.groups, args.seeds, args.stretches, args.offsets)
    print("\n".join(summary(results, args.estimators)))
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))
    return 0 if all(r["pass"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
