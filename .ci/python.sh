#!/usr/bin/env bash
# CI for the Python module (crates/chiaro-py) and distributed rendering on Ray.
# Called by .ci/run after the Rust tests, which leave the CLI binary
# (target/debug/chiaro) and the test-profile build of the workspace behind.
#
# Creates a virtual environment under target/, installs pinned maturin,
# numpy, pytest and ray from PyPI, builds the module into it with the test
# dev profile raised to the test profile's opt-level 2 (so it can reuse the
# artifacts of `cargo test --workspace`; `--profile test` would build a test
# harness, not a loadable library),
# and runs pytest. Fails on any test failure and when no test ran (exit 5).
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

echo "== python: build the chiaro module (maturin develop)"
(
  export VIRTUAL_ENV="$VENV" PATH="$VENV/bin:$PATH"
  CARGO_PROFILE_DEV_OPT_LEVEL=2 maturin develop -m crates/chiaro-py/Cargo.toml
)

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
