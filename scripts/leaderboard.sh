#!/usr/bin/env bash
# Set up a virtual environment (if missing) and run the main job: the leaderboard on the
# default scenarios. Extra arguments go to duallidar-leaderboard (see --help).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/duallidar-leaderboard "$@"
