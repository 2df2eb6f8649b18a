#!/usr/bin/env bash
# Waits until the machine's CPUs are nearly idle (other work on a shared
# machine skews timings), sampling /proc/stat every two seconds.
#   benches/wait_quiet.sh [MAX_WAIT_S=300] [BUSY_PERCENT=8]
# Exit 0 once a sample is at or under BUSY_PERCENT, 1 after MAX_WAIT_S.
max=${1:-300}
limit=${2:-8}
sample() {
  local a b
  read -r _ u n s i w q sq st _ < /proc/stat
  a=$((u + n + s + i + w + q + sq + st)); b=$((i + w))
  sleep 2
  read -r _ u n s i w q sq st _ < /proc/stat
  local total=$((u + n + s + i + w + q + sq + st - a)) idle=$((i + w - b))
  echo $((100 * (total - idle) / (total > 0 ? total : 1)))
}
waited=0
while :; do
  busy=$(sample)
  if [ "$busy" -le "$limit" ]; then
    echo "quiet (${busy}% busy) after ${waited} s"
    exit 0
  fi
  waited=$((waited + 2))
  if [ "$waited" -ge "$max" ]; then
    echo "not quiet (${busy}% busy) after ${waited} s"
    exit 1
  fi
done
