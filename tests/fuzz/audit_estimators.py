"""Issue-18 audit of every registered estimator under clock gaps, bad clocks and scans with
too few returns (not a test; run by hand; categories as in :mod:`tests.fuzz.audit`):

    PYTHONPATH=. .venv/bin/python -m tests.fuzz.audit_estimators [name ...]
"""

import math
import sys

import numpy as np

import estimators
import lidar_env  # noqa: F401
from lidar_env.core.errors import DualLidarError
from tests.estimators.test_faults import hallway_drive

setup, frames = hallway_drive()
counts = {}


def record(cat, outcome, detail=""):
    counts.setdefault(cat, {}).setdefault(outcome, 0)
    counts[cat][outcome] += 1
    if outcome in ("crash", "silent"):
        print(cat, outcome, detail)


names = sys.argv[1:] or estimators.names()
for name in names:

    def fresh(name=name):
        e = estimators.make(name)
        e.reset(setup, frames[0][1])
        return e

    # clock gaps
    for gap in (1.0, 10.0, 60.0, 1e9):
        try:
            e = fresh()
            t = 0.0
            for obs, _ in frames[:-1]:
                p = e.update(obs, t)
                t += 0.1
            ref = fresh()
            tt = 0.0
            for obs, _ in frames:
                truth = ref.update(obs, tt)
                tt += 0.1
            p = e.update(frames[-1][0], t - 0.1 + gap)
            err = float(np.hypot(*(p[:2] - truth[:2])))
            ok = np.all(np.isfinite(p)) and err < 0.5
            record("gap", "correct" if ok else "silent", f"{name} gap {gap}: err {err:.3g}")
        except DualLidarError:
            record("gap", "named")
        except Exception as ex:
            record("gap", "crash", f"{name} gap {gap}: {type(ex).__name__} {ex}")
    # bad clocks
    for bad in (math.nan, math.inf, 1e300, None, "0.5", True, 0.1, 0.0, -1.0):
        try:
            e = fresh()
            e.update(frames[0][0], 0.1)
            e.update(frames[1][0], 0.2)
            p = e.update(frames[2][0], bad)
            record("clock", "silent", f"{name} t={bad!r}: accepted -> {p}")
        except DualLidarError as ex:
            record("clock", "named" if "t:" in str(ex) else "silent", f"{name} {bad!r}: {ex}")
        except Exception as ex:
            record("clock", "crash", f"{name} t={bad!r}: {type(ex).__name__} {ex}")
    # too few returns
    for n_ret in (0, 1, 3, 5):
        try:
            e = fresh()
            t = 0.0
            for obs, _ in frames[:5]:
                e.update(obs, t)
                t += 0.1
            obs = dict(frames[5][0])
            rng = np.random.default_rng(0)
            for key in setup.keys:
                s = np.full_like(np.asarray(obs[key]), setup.max_range)
                idx = rng.choice(len(s), n_ret, replace=False)
                s[idx] = np.asarray(obs[key])[idx]
                obs[key] = s
            before = e.trajectory[-1].copy()
            p = e.update(obs, t)
            jump = float(np.hypot(*(p[:2] - before[:2]))) - float(
                np.hypot(*(frames[5][1][:2] - frames[4][1][:2]))
            )
            ok = np.all(np.isfinite(p)) and jump < 0.5
            record(
                "few_returns",
                "correct" if ok else "silent",
                f"{name} {n_ret} returns: jump {jump:.3g}",
            )
        except DualLidarError:
            record("few_returns", "named")
        except Exception as ex:
            record("few_returns", "crash", f"{name} {n_ret}: {type(ex).__name__} {ex}")
for cat, c in counts.items():
    tried = sum(c.values())
    print(cat, "tried", tried, {k: c.get(k, 0) for k in ("named", "crash", "silent", "correct")})
