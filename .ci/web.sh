#!/usr/bin/env bash
# The web viewer's checks beyond `cargo test`: the tev packets against tev's
# own Python client, and the page in a real headless browser (Debian's
# chromium driven by playwright-core). Called from .ci/run; bounded time.
set -euo pipefail
cd "$(dirname "$0")/.."
E2E=crates/chiaro-serve/e2e
OUT=${WEB_OUT:-target/web-e2e}
mkdir -p "$OUT"

echo "== web: tev protocol against tevclient"
VENV=target/tev-venv
if { [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"; } &&
  timeout 300 "$VENV/bin/pip" install -q tevclient numpy; then
  "$VENV/bin/python" crates/chiaro-serve/tests/fixtures/gen_tev_fixtures.py "$OUT"
  for f in tev_create.bin tev_update.bin; do
    cmp "$OUT/$f" "crates/chiaro-serve/tests/fixtures/$f"
  done
  echo "tevclient produces the committed fixture bytes"
else
  echo "SKIP: tevclient could not be installed; the committed fixtures are still checked by cargo test"
fi

echo "== web: build chiaro and the serve example"
# Release, as the tests are built: a debug radiosity solve takes minutes.
# Two commands: `--example` would apply to both packages and skip the CLI.
cargo build --release -p chiaro-cli
cargo build --release -p chiaro-serve --example serve

echo "== web: chromium"
if [ ! -x /usr/bin/chromium ]; then
  if command -v apt-get >/dev/null; then
    timeout 600 bash -c 'apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null' ||
      echo "apt-get could not install chromium"
  fi
fi
if [ ! -x /usr/bin/chromium ]; then
  echo "SKIP: chromium cannot be installed here; the browser end-to-end test did not run"
  exit 0
fi

echo "== web: end-to-end test in headless chromium"
(cd "$E2E" && timeout 300 npm ci --no-audit --no-fund)
timeout 300 node "$E2E/e2e.mjs" "$OUT"
