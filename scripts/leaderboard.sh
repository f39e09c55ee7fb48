#!/usr/bin/env bash
# Set up a virtual environment (if missing) and run the main job: the leaderboard on the
# default scenarios. Extra arguments go to duallidar-leaderboard (see --help).
set -euo pipefail
cd "$(dirname "$0")/.."
# Set-up installs without byte-compiling (most of its time); Python writes each module's
# bytecode on its first import instead, unless PYTHONDONTWRITEBYTECODE is set (as on this
# machine), when every process compiles every module it imports again: torch ~8 s, the
# estimators' stack ~2 s per leaderboard worker.
unset PYTHONDONTWRITEBYTECODE
bash scripts/setup.sh
.venv/bin/duallidar-leaderboard "$@"
