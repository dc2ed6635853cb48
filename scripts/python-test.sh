#!/usr/bin/env bash
# Builds the Python module (python/: PyO3, built by maturin) in a virtual environment and runs
# its pytest tests (python/tests).
#
#   bash scripts/python-test.sh [pytest arguments...]
#
# The venv is target/python-venv (made with `python3 -m venv`, which on Debian needs the
# python3-venv package; PYTHON=... picks another interpreter), reused by later runs. The wheel
# is built with the dev profile in the workspace's target directory, so dofray is not built
# from scratch each time, and installed into the venv. Exit 3: PyPI could not be reached for
# maturin, pytest or numpy (CI skips the tests with a notice); any other failure, including a
# failing test, exits non-zero.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

python=${PYTHON:-python3}
venv=$root/target/python-venv
wheels=$root/target/python-wheels

if [ ! -x "$venv/bin/python" ]; then
  echo "python-test: making the venv $venv with $($python --version 2>&1)"
  rm -rf "$venv"
  if ! "$python" -m venv "$venv"; then
    echo "python-test: '$python -m venv' failed (on Debian: apt-get install python3-venv)" >&2
    exit 1
  fi
fi
vpy=$venv/bin/python

# The tools, at these versions or newer. Offline, a venv that has them already will do.
requirements=("maturin>=1.9.4,<2" "pytest>=7" "numpy>=1.21")
pip_log=$(mktemp)
trap 'rm -f "$pip_log"' EXIT
if ! "$vpy" -m pip install -q --disable-pip-version-check "${requirements[@]}" >"$pip_log" 2>&1; then
  if "$vpy" -c 'import maturin, pytest, numpy' 2>/dev/null && [ -x "$venv/bin/maturin" ]; then
    echo "python-test: pip install failed; using the venv's maturin, pytest and numpy"
  else
    tail -n 20 "$pip_log" >&2
    echo "python-test: NOTICE: could not install ${requirements[*]} from PyPI; skipped" >&2
    exit 3
  fi
fi

# Build the wheel (the native `linux` tag: the module links the system's Embree) and install it.
rm -rf "$wheels"
"$venv/bin/maturin" build -m python/Cargo.toml -i "$vpy" --out "$wheels" \
  --compatibility linux --auditwheel skip
"$vpy" -m pip install -q --disable-pip-version-check --no-deps --force-reinstall "$wheels"/dofray-*.whl

# From python/tests (not python/), so `import dofray` is the installed package, not the source.
cd python/tests
"$vpy" -m pytest -p no:cacheprovider "$@" .
