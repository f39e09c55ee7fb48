"""Cold start: a new process's first ``import lidar_env`` + ``gym.make`` + ``reset`` + ``step``.

    python benchmarks/bench_cold_start.py              # as a user meets it, and make_vec(32)
    python benchmarks/bench_cold_start.py --empty-cache  # and against an empty numba cache

Each figure comes from a fresh Python process (``sys.executable``), timed inside it: wall and
CPU seconds of the import, of ``gym.make("DualLidar-v0")``, its ``reset`` and first ``step``,
and of ``gym.make_vec(..., num_envs=N, vectorization_mode="vector_entry_point")`` with its
reset and step, plus how many numba kernels the process compiled (numba's compile events).
After ``scripts/setup.sh`` it compiles none: the kernels load from numba's cache in
``__pycache__``. ``--empty-cache`` adds the same process with ``NUMBA_CACHE_DIR`` pointed at an
empty directory (every kernel compiles; the clone's cache is left alone) and prints the ratio
of the two, measured in this run. ``--json OUT`` writes every figure and each target's verdict
(``python benchmarks/publish.py cold_start`` publishes them).

Targets, after ``scripts/setup.sh``: the first ``import`` + ``gym.make`` + ``reset`` + ``step``
in at most 5 s wall, ``make_vec`` of 32 envs + ``reset`` + ``step`` after it in at most 8 s
wall, and no kernel compiled.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: [s] wall, a fresh process's first import + gym.make + reset + step.
TARGET_FIRST_STEP_S = 5.0
#: [s] wall, make_vec(N) + reset + step after the first step.
TARGET_VECTOR_S = 8.0
#: Runs in the child: the phases' wall and CPU seconds and the compile count, as JSON.
PROBE = """
import json, sys, time
w0, c0 = time.perf_counter(), time.process_time()
import numba.core.event as event
compiled = []
class Count(event.Listener):
    def on_start(self, e): compiled.append(1)
    def on_end(self, e): pass
event.register("numba:compile", Count())
phases = {}
def mark(name, wall, cpu):
    phases[name] = [time.perf_counter() - wall, time.process_time() - cpu]
    return time.perf_counter(), time.process_time()
w, c = w0, c0
import gymnasium as gym
import numpy as np
import lidar_env
w, c = mark("import", w, c)
env = gym.make("DualLidar-v0")
w, c = mark("make", w, c)
env.reset(seed=0)
w, c = mark("reset", w, c)
env.step(env.action_space.sample())
w, c = mark("step", w, c)
phases["first step"] = [w - w0, c - c0]
n = int(sys.argv[1])
if n:
    envs = gym.make_vec("DualLidar-v0", num_envs=n, vectorization_mode="vector_entry_point")
    envs.reset(seed=0)
    envs.step(np.zeros((n, 2), np.float32))
    w, c = mark(f"make_vec({n}) + reset + step", w, c)
print(json.dumps({"phases": phases, "compiled": len(compiled)}))
"""


def probe(num_envs: int, cache_dir: str | None) -> dict[str, Any]:
    """One fresh process's phases; ``cache_dir`` overrides numba's cache location."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    done = subprocess.run([sys.executable, "-c", PROBE, str(num_envs)], cwd=ROOT, env=env,
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def show(label: str, result: dict[str, Any]) -> None:
    print(f"{label}: {result['compiled']} numba kernels compiled")
    for phase, (wall, cpu) in result["phases"].items():
        print(f"  {phase:32s} {wall:7.2f} s wall {cpu:7.2f} s CPU")


def vector_phase(num_envs: int) -> str:
    """The probe's name of the batched env's phase."""
    return f"make_vec({num_envs}) + reset + step"


def targets(cached: dict[str, Any], num_envs: int) -> list[dict[str, Any]]:
    """Each target with the figure measured for it and whether it is met, printed."""
    found = [{"target": f"first import + gym.make + reset + step <= {TARGET_FIRST_STEP_S:g} s "
                        "wall", "value": cached["phases"]["first step"][0],
              "threshold": TARGET_FIRST_STEP_S}]
    if num_envs:
        found.append({"target": f"{vector_phase(num_envs)} <= {TARGET_VECTOR_S:g} s wall",
                      "value": cached["phases"][vector_phase(num_envs)][0],
                      "threshold": TARGET_VECTOR_S})
    for target in found:
        target["met"] = bool(target["value"] <= target["threshold"])
    found.append({"target": "kernels compiled after scripts/setup.sh = 0",
                  "value": cached["compiled"], "threshold": 0,
                  "met": cached["compiled"] == 0})
    for target in found:
        print(f"target {target['target']}: {target['value']:.3g} "
              f"{'meets' if target['met'] else 'misses'} it")
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--vector", type=int, default=32, metavar="N",
                        help="envs of the batched env to make after the single one (0: none)")
    parser.add_argument("--empty-cache", action="store_true",
                        help="also run against an empty numba cache, and print the ratio")
    parser.add_argument("--json", type=Path, default=None,
                        help="also write every figure here (phases, compiles, ratios, targets)")
    args = parser.parse_args(argv)
    if args.vector < 0:
        parser.error(f"--vector: expected a count >= 0, got {args.vector}")
    load = os.getloadavg()[0]
    machine = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
               f"python {platform.python_version()}")
    print(f"machine: {machine}, load average {load:.1f}")
    cached = probe(args.vector, None)
    show("this clone's numba cache (a user's first run after scripts/setup.sh)", cached)
    report: dict[str, Any] = {"machine": machine, "load_average": load, "vector": args.vector,
                              "cached": cached, "empty_cache": None, "ratios": {}}
    if args.empty_cache:
        with tempfile.TemporaryDirectory() as empty:
            cold = probe(args.vector, empty)
        show("an empty numba cache (every kernel compiles)", cold)
        report["empty_cache"] = cold
        for phase, (wall, cpu) in cached["phases"].items():
            cold_wall, cold_cpu = cold["phases"][phase]
            ratios = [cold_wall / wall, cold_cpu / max(cpu, 1e-9)]
            report["ratios"][phase] = ratios
            print(f"  {phase:32s} empty cache / this cache: {ratios[0]:6.1f}x wall "
                  f"{ratios[1]:6.1f}x CPU")
    report["targets"] = targets(cached, args.vector)
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
