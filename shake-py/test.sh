#!/usr/bin/env bash
# Builds the Python package as the abi3 wheel a user would install, installs
# it into a virtual environment and runs the package's tests against it:
#   bash shake-py/test.sh [pytest arguments]
# Needs Rust and Python 3 (with venv; installed with apt-get when missing).
# The tests run from a directory without the package's sources and with no
# cargo, rustc or maturin on PATH, so what is tested is the installed wheel.
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
out="$CARGO_TARGET_DIR/wheels"
rm -rf "$out"
(cd "$here" && VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" maturin build --release -q --out "$out")
wheel=$(ls "$out"/geoshake-*-abi3-*.whl)
echo "wheel: $(basename "$wheel")"
# --force-reinstall: a rebuilt wheel keeps its version number; --no-deps: its
# one dependency, numpy, is installed above and need not be fetched again.
"$venv/bin/python" -m pip install -q --force-reinstall --no-deps "$wheel"
# Nothing of Rust on PATH while the tests run: the wheel must not need it.
clean_path="$venv/bin:/usr/bin:/bin"
if PATH="$clean_path" command -v cargo >/dev/null; then
    echo "note: cargo is in /usr/bin, so this run does not show the wheel works without Rust" >&2
fi
cd "$(mktemp -d)"
PATH="$clean_path" "$venv/bin/python" -c 'import geoshake; print("imported", geoshake.__file__)'
# -rs: a skipped test prints its reason.
PATH="$clean_path" "$venv/bin/python" -m pytest -q -rs -p no:cacheprovider "$here/tests" "$@"
