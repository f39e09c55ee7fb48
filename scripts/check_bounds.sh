#!/usr/bin/env bash
# Check that pyproject.toml's lower bounds are true: install the LOWEST version each core
# dependency allows (">=X" -> "==X") into a throw-away venv, the project itself with --no-deps,
# then run a smoke test: import lidar_env, gym.make("DualLidar-v0"), reset, 20 steps, the batched
# env with 2 envs, and one estimator over the steps. A bound that fails here must be raised.
#
#   bash scripts/check_bounds.sh            # with python3.10 (requires-python's floor) if found
#   PYTHON=python3.11 bash scripts/check_bounds.sh
#
# Nothing in .venv/ is touched; the throw-away venv is deleted on exit (KEEP=1 keeps it).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${PYTHON:-}" ]; then
    PYTHON=python3
    # requires-python's floor, 3.10: on PATH, or installed by pyenv but not selected
    for candidate in python3.10 "$(pyenv root 2>/dev/null)"/versions/3.10*/bin/python3.10; do
        if "$candidate" -c "" >/dev/null 2>&1; then PYTHON="$candidate"; break; fi
    done
fi
venv="$(mktemp -d)/bounds"
[ "${KEEP:-0}" = 1 ] || trap 'rm -rf "$(dirname "$venv")"' EXIT
"$PYTHON" -m venv "$venv"
py="$venv/bin/python"
echo "check-bounds: $("$py" --version) in $venv"
quiet() { "$@" 2>&1 | { grep -v "^WARNING: Location '.*' is ignored" || true; }; }
quiet "$py" -m pip install -q --upgrade pip
# Each core dependency at the lowest version its specifier allows (torch is no core dependency).
mapfile -t lowest < <("$PYTHON" - <<'PY'
import re
from pathlib import Path

text = Path("pyproject.toml").read_text()
block = re.search(r"^dependencies = \[(.*?)^\]", text, flags=re.S | re.M)[1]
for requirement in re.findall(r'"([^"]+)"', block):
    match = re.fullmatch(r"([A-Za-z0-9_.\-\[\]]+)\s*>=\s*([0-9][0-9A-Za-z.]*)", requirement)
    if match is None:
        raise SystemExit(f"check-bounds: cannot read a lower bound from {requirement!r}")
    print(f"{match[1]}=={match[2]}")
PY
)
echo "check-bounds: installing ${lowest[*]}"
quiet "$py" -m pip install -q "${lowest[@]}"
quiet "$py" -m pip install -q --no-deps .
"$py" -m pip list --format=freeze 2>/dev/null \
    | grep -iE "^(gymnasium|numpy|scipy|pymunk|numba|llvmlite|tqdm|pillow)==" \
    | sed 's/^/check-bounds: installed /'
cd "$(dirname "$venv")"  # import the installed project, not this folder by accident
"$py" - <<'PY'
import time
from importlib import resources

import gymnasium as gym
import numpy as np

import lidar_env  # noqa: F401  registers DualLidar-v0

for package in ("lidar_env", "estimators", "agents"):
    assert resources.files(package).joinpath("py.typed").is_file(), f"{package} lacks py.typed"
started = time.perf_counter()
env = gym.make("DualLidar-v0", world="hallway", trace="zigzag")
observation, info = env.reset(seed=0)
assert set(observation) == {"lidar_1", "lidar_2"}, observation.keys()
import estimators

estimator = estimators.make("icp")
estimator.reset(estimators.SensorSetup.from_env(env), initial_pose=info["pose"])
for _ in range(20):
    estimator.update(observation, info["time"])
    observation, reward, terminated, truncated, info = env.step(np.array([0.5, 0.1], np.float32))
    assert not (terminated or truncated)
assert np.isfinite(estimator.trajectory).all()
env.close()
venv = gym.make_vec("DualLidar-v0", num_envs=2, vectorization_mode="vector_entry_point")
observations, infos = venv.reset(seed=0)
for _ in range(20):
    observations, rewards, terminations, truncations, infos = venv.step(
        np.zeros((2, 2), np.float32))
assert observations["lidar_1"].shape == (2, 360), observations["lidar_1"].shape
venv.close()
print(f"check-bounds: smoke test passed ({time.perf_counter() - started:.0f} s)")
PY
