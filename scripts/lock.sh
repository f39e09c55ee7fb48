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
# The [dev] extra names the project itself (duallidar[agents,...]): pip-compile pins it as
# "duallidar @ file:///<this checkout>", which would install a copy of *this* folder in every
# clone. setup.sh installs the project editable instead, so the line is dropped.
python3 - <<'PY'
import re
from pathlib import Path
lock = Path("requirements.lock")
text = re.sub(r"^duallidar @ file:\S+\n(    #.*\n)*", "", lock.read_text(), flags=re.M)
lock.write_text(text)
PY
echo "requirements.lock refreshed: review 'git diff requirements.lock' and commit it"
