#!/usr/bin/env bash
# The suboptimal regime under its other reading (turn around and back), for leaderboard/README.md; published with
# ceil rounding (the cards' default, spelled out).
set -euo pipefail
cd "$(dirname "$0")/.."
export GRAIL_BENCH_STORE=leaderboard/readings.sqlite
for t in Suboptimal Suboptimal-4Goals Suboptimal-6Goals; do
  .venv/bin/grail-bench run -t GRAIL/MiniGrid-$t-v0 -r bc -r graql --param turn_pattern=around-and-back --rounding ceil \
      --seeds 10 \
      --no-progress --json leaderboard/results/MiniGrid-$t-around-and-back-bc-graql.json
done
