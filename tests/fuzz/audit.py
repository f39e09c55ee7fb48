"""Issue-18 audit: count outcomes of random faults per category (not a test; run by hand).

    PYTHONPATH=. .venv/bin/python -m tests.fuzz.audit

Each trial is "named" (a DualLidarError), "crash" (any other exception), "silent" (accepted,
but the result fails the category's oracle) or "correct" (accepted and passes it).
"""

from __future__ import annotations

import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

from estimators.datasets.carmen import load_log
from estimators.leaderboard.database import ExperimentDatabase
from estimators.slam.g2o import read_g2o
from estimators.slam.solver import optimize
from lidar_env.core.errors import DualLidarError
from lidar_env.world.world import World
from tests.fuzz.test_fuzz_logs import CARMEN, G2O

TOKENS = ["nan", "inf", "-inf", "-1", "0", "1", "2", "abc", "", "1e308", "4294967296",
          "1" * 30, "\xe9", "1e200", "-2.5", "3"]


def outcome(trial, check) -> str:
    try:
        result = trial()
    except DualLidarError:
        return "named"
    except Exception as error:  # noqa: BLE001 - counting what escapes is the point
        print(f"  crash: {type(error).__name__}: {str(error)[:100]}")
        return "crash"
    return "correct" if check(result) else "silent"


def mutate(lines: list[str], rng: np.random.Generator) -> str:
    lines = list(lines)
    index = int(rng.integers(len(lines)))
    words = lines[index].split()
    k = int(rng.integers(len(words)))
    action = rng.integers(4)
    if action == 0:
        words[k] = str(rng.choice(TOKENS))
    elif action == 1:
        del words[k]
    elif action == 2:
        words.insert(k, words[k])
    else:
        words = words[:k]
    lines[index] = " ".join(words)
    return "\n".join(lines) + "\n"


def carmen_ok(log) -> bool:
    return all(len(s.ranges) == len(s.angles) >= 2 and np.all(np.isfinite(s.ranges))
               and np.all(s.ranges >= 0) and np.all(np.isfinite(s.laser_offset))
               for s in log.scans)


def g2o_ok(graph) -> bool:
    try:
        result = optimize(graph)
    except DualLidarError:
        return True
    return bool(np.all(np.isfinite(result.poses)))


def main() -> None:
    rng = np.random.default_rng(18)
    table: dict[str, Counter] = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "f"
        for category, lines, reader, check, n in (
            ("CARMEN lines", CARMEN, load_log, carmen_ok, 600),
            ("g2o lines", G2O, read_g2o, g2o_ok, 300),
        ):
            counts = table.setdefault(category, Counter())
            for _ in range(n):
                path.write_text(mutate(lines, rng), encoding="utf-8")
                counts[outcome(lambda r=reader: r(path), check)] += 1
        counts = table.setdefault("map images", Counter())
        for _ in range(300):
            shape = tuple(int(s) for s in rng.integers(0, 20, rng.integers(1, 4)))
            image = rng.choice([0.0, 1.0, 255.0, np.nan, -1.0], size=shape,
                               p=[0.6, 0.2, 0.17, 0.015, 0.015])
            resolution = rng.choice([0.05, 1.0, 0.0, -1.0, np.inf])
            counts[outcome(lambda i=image, r=resolution: World.from_image(i, r),
                           lambda w, i=image, r=resolution: np.array_equal(
                               w.to_image(r) > 0, i > 0))] += 1
        counts = table.setdefault("World geometry", Counter())
        for _ in range(300):
            def values(width):
                v = rng.normal(0, 5, (int(rng.integers(0, 4)), width)).tolist()
                if v and rng.random() < 0.3:
                    v[0][0] = rng.choice([np.nan, np.inf, "x", 1e300])
                return v
            polygons = [rng.normal(0, 3, (int(rng.integers(3, 7)), 2)) for _ in range(2)]
            counts[outcome(lambda p=polygons: World(values(3), values(4), p),
                           lambda w: bool(np.all(np.isfinite(w.bounds))))] += 1
        counts = table.setdefault("database overwrites", Counter())
        from tests.estimators.leaderboard.test_database import (
            SCENARIO,
            synthetic_dataset,
            synthetic_trace,
        )
        db_path = Path(tmp) / "db.sqlite"
        dataset, trace = synthetic_dataset(rng), synthetic_trace(rng)
        with ExperimentDatabase(db_path) as db:
            db.save_sensor_dataset(SCENARIO, dataset)
            db.save_trace(SCENARIO, trace, {"ate_m": 0.5})
        pristine = db_path.read_bytes()
        for _ in range(40):
            data = bytearray(pristine)
            start = int(rng.integers(4096, len(data) - 64))
            data[start:start + 64] = rng.integers(0, 256, 64, dtype=np.uint8).tobytes()
            db_path.write_bytes(bytes(data))

            def read():
                with ExperimentDatabase(db_path) as db:
                    return db.load_sensor_dataset(SCENARIO), db.traces()[0]

            counts[outcome(read, lambda r: np.array_equal(r[0].poses, dataset.poses)
                           and np.array_equal(r[1].trace.poses, trace.poses))] += 1
    print(f"{'category':22} tried named crash silent correct")
    for category, counts in table.items():
        print(f"{category:22} {sum(counts.values()):5} {counts['named']:5} {counts['crash']:5} "
              f"{counts['silent']:6} {counts['correct']:7}")


if __name__ == "__main__":
    main()
