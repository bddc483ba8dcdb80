#!/usr/bin/env bash
# Creates (or updates) the project-local virtualenv .venv with the bridges' Python packages
# from PyPI, and prints its interpreter's path.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
venv="$root/.venv"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv" >&2
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$root/bridges/python/requirements.txt" >&2
echo "$venv/bin/python"
