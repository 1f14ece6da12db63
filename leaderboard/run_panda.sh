#!/usr/bin/env bash
# PandaReach runs behind leaderboard/ (see leaderboard/README.md), both goal sets, seeds added in rounds.
set -euo pipefail
cd "$(dirname "$0")/.."
export GRAIL_BENCH_STORE=leaderboard/results.sqlite
GB=".venv/bin/grail-bench"
for n in 1 2 3; do
  for t in Optimal Gaussian-0.1 Gaussian-0.3 Uniform-0.1 Uniform-0.3 Aligned-Optimal Aligned-Gaussian-0.1 \
           Aligned-Gaussian-0.3 Aligned-Uniform-0.1 Aligned-Uniform-0.3; do
    $GB run -t GRAIL/PandaReach-$t-v0 -r bc -r draco --scorer mse --scorer wasserstein --scorer loglik \
        --seeds $n --no-progress --json leaderboard/results/PandaReach-$t-bc-draco.json
  done
done
