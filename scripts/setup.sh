#!/usr/bin/env bash
# Create .venv and install exactly requirements.lock (every dependency of every extra, pinned;
# uv installs it), then the project itself (editable). torch is the CPU build 2.13.0, installed
# first, by pip from this machine's file, so that no step ever resolves a multi-GB CUDA build. Nothing is installed when requirements.lock,
# pyproject.toml and this script are unchanged since the last successful set-up.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"
# The installer of the lock (pip installs it, with torch, into .venv).
UV_VERSION=0.13.9
# The leaderboard report's test renders report.html in a headless browser: Debian's chromium,
# installed quietly when missing; without apt-get (or when it fails) one line says so and that
# test skips. It installs in the background, beside the Python install and the compile (about
# 20 s of a fresh machine's set-up), and its line comes at the end.
install_chromium() {
    command -v chromium >/dev/null 2>&1 && return 0
    local apt=(env DEBIAN_FRONTEND=noninteractive apt-get -qq -y)
    [ "$(id -u)" = 0 ] || apt=(sudo -n "${apt[@]}")
    if command -v apt-get >/dev/null 2>&1 && { "${apt[@]}" install chromium >/dev/null 2>&1 \
            || { "${apt[@]}" update >/dev/null 2>&1 \
                 && "${apt[@]}" install chromium >/dev/null 2>&1; }; }; then
        echo "set-up: installed chromium (headless browser for the report test)"
    else
        echo "set-up: chromium not installed (no apt-get, or it failed): the report's browser test skips"
    fi
}
chromium_log="$(mktemp)"
install_chromium >"$chromium_log" 2>&1 </dev/null &
chromium_job=$!
finish_chromium() { wait "$chromium_job" || true; cat "$chromium_log"; rm -f "$chromium_log"; }
trap finish_chromium EXIT
stamp=.venv/.setup-stamp
wanted="$(cat requirements.lock pyproject.toml scripts/setup.sh | sha256sum | cut -d' ' -f1)"
if [ -x .venv/bin/python ] && [ "$(cat "$stamp" 2>/dev/null)" = "$wanted" ]; then
    echo "set-up: .venv matches requirements.lock (delete .venv/.setup-stamp to reinstall)"
else
    started=$SECONDS
    stale=1
    [ -x .venv/bin/python ] || { "$PYTHON" -m venv .venv; stale=0; }
    rm -f "$stamp"
    # pip warns about every package missing from this machine's local file indexes: noise, not news.
    # --no-compile: byte-compiling torch's and scipy's thousands of modules up front was most of the
    # set-up time; Python compiles each module once, on its first import, instead.
    quiet() { "$@" 2>&1 | { grep -v "^WARNING: Location '.*' is ignored" || true; }; }
    pip=(.venv/bin/python -m pip -q)
    quiet "${pip[@]}" install --no-compile --no-deps "torch==2.13.0" "uv==$UV_VERSION"
    # The rest of the lock with uv: the same pins, fetched and unpacked in parallel (about 15 s
    # where pip took about 50). torch is already there at the lock's version, so uv, which does
    # not look at this machine's torch file, leaves it alone. An older .venv may hold packages
    # the lock no longer names: "uv pip sync" removes them.
    uv=(env VIRTUAL_ENV=.venv UV_PYTHON=.venv/bin/python .venv/bin/uv pip)
    if [ "$stale" = 0 ]; then
        "${uv[@]}" install -q --no-deps -r requirements.lock
    else
        "${uv[@]}" sync -q requirements.lock
    fi
    # setuptools warns that a flat layout's editable install sees same-named folders in the working
    # directory; that is how this project is meant to run, so the warning is filtered.
    PYTHONWARNINGS="ignore:Editable installation" \
        quiet "${pip[@]}" install --no-compile --no-deps --no-build-isolation -e .
    .venv/bin/python scripts/check_lock.py
    echo "$wanted" > "$stamp"
    echo "set-up: .venv holds requirements.lock ($((SECONDS - started)) s)"
fi
# numba compiles each kernel on its first call and caches the machine code in __pycache__: done
# here once per source (two processes; instant when this source's marker exists), so that no
# run, the first env step and the leaderboard's first run included, waits for a compiler.
# With bytecode written (as leaderboard.sh and test.sh do), so the modules it imports load
# from .pyc in the processes after it.
env -u PYTHONDONTWRITEBYTECODE .venv/bin/python scripts/compile_kernels.py \
    || echo "set-up: a kernel did not compile (see above); runs compile what they use"
