#!/usr/bin/env bash
# Builds the abi3 wheel with maturin and tests it as a user would install it:
# into a fresh virtual environment, with no Rust toolchain on PATH.
#   bash shake-py/wheel_test.sh      (after shake-py/test.sh made its venv)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
build_venv="${SHAKE_PY_VENV:-$here/../target/shake-py-venv}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$here/../target}"
out="$CARGO_TARGET_DIR/wheels"
rm -rf "$out"
(cd "$here" && VIRTUAL_ENV="$build_venv" PATH="$build_venv/bin:$PATH" maturin build --release -q --out "$out")
wheel=$(ls "$out"/geoshake-*-abi3-*.whl)
echo "wheel: $(basename "$wheel")"
fresh="$CARGO_TARGET_DIR/wheel-venv"
rm -rf "$fresh"
python3 -m venv "$fresh"
"$fresh/bin/python" -m pip install -q "$wheel" pytest
# No cargo, rustc or maturin on PATH: the wheel must not need them.
clean_path="$fresh/bin:/usr/bin:/bin"
if PATH="$clean_path" command -v cargo >/dev/null; then
    echo "cargo is in /usr/bin; the no-Rust check would prove nothing" >&2
    exit 1
fi
# Run the suite from a directory without the package's sources, so the
# installed wheel is what is imported.
cd "$(mktemp -d)"
PATH="$clean_path" "$fresh/bin/python" -c 'import geoshake, sys; print("imported", geoshake.__file__)'
# -rs: the ASE comparisons skip here (no ASE in this venv) and say so.
PATH="$clean_path" "$fresh/bin/python" -m pytest -q -rs "$here/tests" -p no:cacheprovider
