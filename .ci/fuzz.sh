#!/usr/bin/env bash
# CI fuzz stage: mutates scenes through the CLI (fuzz/mutate.py, no nightly
# needed), then builds the cargo-fuzz targets in fuzz/ and runs each from
# its checked-in corpus for a bounded time (FUZZING.md). A crash (or a hang,
# for the CLI mutation and the `techniques` target) fails the stage and
# leaves its input under fuzz/artifacts/.
# FUZZ_SECONDS (default 10) bounds each target's run; FUZZ_SEED (default 1)
# fixes libFuzzer's random choices, so a commit's CI run explores the same
# inputs each time (a crash is the code's, not the dice's).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never
seconds="${FUZZ_SECONDS:-10}"
seed="${FUZZ_SEED:-1}"

skip() {
  echo "SKIP fuzz: $*"
  exit 0
}

# CLI-level mutation fuzzing (fuzz/mutate.py): needs no nightly, so it runs
# everywhere; mutants of the shipped scenes and corpora through `chiaro info`
# and `chiaro render` under a 4 GB address-space cap, a hang, crash, panic
# or Debug-form message fails the stage (input under fuzz/artifacts/cli/).
if command -v python3 >/dev/null 2>&1; then
  cargo build --release -p chiaro-cli
  echo "== mutate (CLI, ${seconds} s)"
  python3 fuzz/mutate.py --chiaro target/release/chiaro --seconds "$seconds" --seed "$seed" ||
    { echo "CLI mutation found a problem: see fuzz/artifacts/cli/"; exit 1; }
else
  echo "SKIP mutate: no python3"
fi

# cargo-fuzz needs a nightly compiler (libFuzzer's coverage flags).
if ! cargo +nightly --version >/dev/null 2>&1; then
  rustup toolchain install nightly --profile minimal ||
    skip "no nightly toolchain could be installed (rustup toolchain install nightly failed)"
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
  cargo install cargo-fuzz --locked ||
    skip "cargo-fuzz could not be installed (cargo install cargo-fuzz failed)"
fi
cargo +nightly --version
cargo fuzz --version

# No sanitizer: chiaro forbids unsafe code, and without AddressSanitizer the
# build is about half as long and runs twice as fast; debug assertions and
# overflow checks stay on (cargo fuzz's default release build).
cd fuzz
targets=$(cargo fuzz list)
start=$(date +%s)
cargo +nightly fuzz build --sanitizer none
echo "built in $(($(date +%s) - start)) s"

for t in $targets; do
  mkdir -p "corpus/$t"
  # Fuzz into a scratch copy so that CI never grows the checked-in corpus.
  work=$(mktemp -d)
  cp -r "corpus/$t/." "$work/"
  # One input of `techniques` renders every technique (about 12 s in this
  # debug-assertion build on 2 cores, 41 s for the slowest seed), so its hang
  # timeout is longer.
  per_input=10
  [ "$t" = techniques ] && per_input=120
  echo "== fuzz $t (${seconds} s, ${per_input} s an input)"
  log="$work.log"
  set +e
  cargo +nightly fuzz run --sanitizer none "$t" "$work" -- \
    -max_total_time="$seconds" -seed="$seed" -timeout="$per_input" -rss_limit_mb=2048 -max_len=262144 \
    -print_final_stats=1 >"$log" 2>&1
  status=$?
  set -e
  grep -E "^(#[0-9]+ +DONE|stat::number_of_executed_units|stat::peak_rss_mb|SUMMARY|Test unit written)" "$log" || true
  if [ "$status" -ne 0 ]; then
    tail -n 40 "$log"
  fi
  rm -rf "$work" "$log"
  if [ "$status" -ne 0 ]; then
    echo "fuzz target $t failed: its input is in fuzz/artifacts/$t/"
    exit 1
  fi
done
echo "fuzz stage: $(($(date +%s) - start)) s"
