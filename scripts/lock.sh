#!/usr/bin/env bash
# Refresh requirements.lock from pyproject.toml ([dev], every extra) and requirements.in, with
# pip-tools' pip-compile in a throw-away venv. Run it after changing a dependency; commit both.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"
tools="$(mktemp -d)"
trap 'rm -rf "$tools"' EXIT
"$PYTHON" -m venv "$tools"
"$tools/bin/python" -m pip install -q "pip-tools==7.6.2" 2>&1 | grep -v "^WARNING: Location" || true
"$tools/bin/pip-compile" -q --strip-extras --allow-unsafe --no-emit-find-links \
    --no-emit-index-url --extra dev --output-file requirements.lock pyproject.toml requirements.in
echo "requirements.lock refreshed: review 'git diff requirements.lock' and commit it"
