#!/usr/bin/env bash
# Builds the Python package into a virtual environment and runs its tests:
#   bash shake-py/test.sh
# Needs Rust and Python 3 (with venv; installed with apt-get when missing).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
venv="${SHAKE_PY_VENV:-$here/../target/shake-py-venv}"
if ! python3 -c 'import venv, ensurepip' 2>/dev/null; then
    if command -v apt-get >/dev/null; then
        apt-get update -qq && apt-get install -y -qq python3-venv
    else
        echo "python3 venv module missing" >&2
        exit 1
    fi
fi
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/python" -m pip install -q --upgrade pip
"$venv/bin/python" -m pip install -q "maturin>=1.5,<2" numpy pytest
# ASE, for the comparisons with its own FixBondLengths; without a package
# index it cannot be installed, and tests/test_ase.py says it skips.
"$venv/bin/python" -m pip install -q ase ||
    echo "ASE could not be installed: tests/test_ase.py will be skipped" >&2
# Into the shared target dir, so the workspace's compiled crates are reused.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$here/../target}"
(cd "$here" && VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" maturin develop --release -q)
# -rs: a skipped test prints its reason.
cd "$here" && "$venv/bin/python" -m pytest -q -rs tests "$@"
