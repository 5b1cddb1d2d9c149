#!/usr/bin/env bash
# Everything the tests need beyond Rust, made idempotently: the README's test command runs it
# first, and so does .ci/run (through that command).
#
#   .venv-ci/                   Python venv with the pinned packages of tools/requirements-ci.txt
#                               (the stock iceoryx2 package, Ray, ...) and, when python/ exists,
#                               the `agp` package installed from it
#   tools/foxglove-client/      the stock Foxglove client and what the browser check drives (npm ci)
#   /usr/bin/chromium           Debian's Chromium, for the browser check (apt-get, root only)
#
# A second run installs nothing: each step keeps a stamp of what it installed (a hash of its
# inputs) and does its work only when that changed. Every line it prints starts with
# `setup:`; a step that fails names itself and the command to run by hand.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"

say() { printf 'setup: %s\n' "$*"; }
fail() { printf 'setup: error: %s\n' "$*" >&2; exit 1; }

# The hash of files (missing ones count as empty), for the stamps.
hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }

# --- Python ---------------------------------------------------------------------------------
venv="$repo/.venv-ci"
requirements="$repo/tools/requirements-ci.txt"
command -v python3 >/dev/null || fail "no python3 on PATH: install Python 3.11 or later"
if [ ! -x "$venv/bin/python" ]; then
    say "making the Python venv .venv-ci"
    python3 -m venv "$venv" || fail "python3 -m venv .venv-ci failed"
fi
py_inputs=("$requirements")
if [ -f python/pyproject.toml ]; then
    while IFS= read -r f; do py_inputs+=("$f"); done < <(find python -type f \
        \( -name '*.py' -o -name '*.toml' -o -name 'py.typed' -o -name '*.cfg' \) \
        -not -path '*/build/*' -not -path '*.egg-info/*' -not -path '*/__pycache__/*' | sort)
fi
py_hash="$(hash_of "${py_inputs[@]}")"
py_stamp="$venv/.agp-setup-stamp"
if [ "$(cat "$py_stamp" 2>/dev/null)" != "$py_hash" ]; then
    say "installing the pinned Python packages (tools/requirements-ci.txt) into .venv-ci"
    "$venv/bin/pip" install --quiet --disable-pip-version-check -r "$requirements" \
        || fail "pip install -r tools/requirements-ci.txt failed"
    if [ -f python/pyproject.toml ]; then
        say "installing the agp Python package from python/ into .venv-ci"
        "$venv/bin/pip" install --quiet --disable-pip-version-check --no-deps --force-reinstall ./python \
            || fail "pip install ./python failed"
        rm -rf python/build python/*.egg-info python/src/*.egg-info
    fi
    echo "$py_hash" > "$py_stamp"
else
    say "Python packages up to date (.venv-ci)"
fi

# --- npm ------------------------------------------------------------------------------------
command -v npm >/dev/null || fail "no npm on PATH: install Node.js 20 or later with npm"
for dir in tools/foxglove-client; do
    lock="$dir/package-lock.json"
    npm_hash="$(hash_of "$lock" "$dir/package.json")"
    npm_stamp="$dir/node_modules/.agp-setup-stamp"
    if [ "$(cat "$npm_stamp" 2>/dev/null)" != "$npm_hash" ]; then
        say "installing the npm packages of $dir (npm ci)"
        (cd "$dir" && npm ci --no-audit --no-fund --loglevel=error >/dev/null) || fail "npm ci in $dir failed"
        echo "$npm_hash" > "$npm_stamp"
    else
        say "npm packages up to date ($dir)"
    fi
done

# --- Chromium (the browser check) -------------------------------------------------------------
if [ ! -x /usr/bin/chromium ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        say "installing Debian's chromium (apt-get)"
        { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; } \
            || fail "apt-get install chromium failed"
    else
        fail "no /usr/bin/chromium: run \`sudo apt-get install chromium\` (the browser check needs it)"
    fi
else
    say "chromium present (/usr/bin/chromium)"
fi
say "done"
