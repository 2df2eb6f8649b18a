#!/usr/bin/env bash
# CI for the Python module (crates/chiaro-py) and distributed rendering on Ray.
# Called by .ci/run after the Rust tests (`cargo test --release --workspace`),
# whose release artefacts the wheel build reuses.
#
# Creates a virtual environment under target/, installs pinned maturin,
# numpy, pytest and ray from PyPI, builds the abi3 wheel with maturin
# (release profile, the workspace's x86-64-v3 target), installs that wheel
# file with pip, and runs pytest. Fails on any test failure and when no test
# ran (exit 5).
set -euo pipefail
cd "$(dirname "$0")/.."

VENV="$PWD/target/python-ci"
PY="${PYTHON:-python3}"

echo "== python: virtual environment ($VENV)"
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" --version
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
  "maturin==1.16.0" "numpy==2.4.6" "pytest==9.2.0" "ray==2.60.0"

echo "== python: build the abi3 wheel (maturin build --release) and pip install it"
WHEELS="$PWD/target/python-ci-wheels"
rm -rf "$WHEELS"
"$VENV/bin/maturin" build --release -m crates/chiaro-py/Cargo.toml -o "$WHEELS"
ls "$WHEELS"
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps "$WHEELS"/chiaro-*-abi3-*.whl

echo "== python: pytest"
export RAY_USAGE_STATS_ENABLED=0
set +e
"$VENV/bin/python" -m pytest -p no:cacheprovider -q -o addopts="" crates/chiaro-py/tests
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
  echo "python: pytest collected no tests; treating that as a failure" >&2
  exit 1
fi
exit "$rc"
