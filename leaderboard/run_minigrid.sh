#!/usr/bin/env bash
# MiniGrid runs behind leaderboard/ (see leaderboard/README.md). Seeds are added in rounds, so a stopped
# sweep resumes from the store where it stopped.
set -euo pipefail
cd "$(dirname "$0")/.."
export GRAIL_BENCH_STORE=leaderboard/results.sqlite
GB=".venv/bin/grail-bench"
SCORERS="--scorer mse --scorer kl --scorer wasserstein --scorer loglik"
TASKS="Optimal Optimal-4Goals Optimal-6Goals Suboptimal Suboptimal-4Goals Suboptimal-6Goals Biased"
for t in $TASKS; do  # the task's default protocol: subset (biased: prefix)
  $GB run -t GRAIL/MiniGrid-$t-v0 -r bc -r graql $SCORERS --seeds 10 --no-progress --json leaderboard/results/MiniGrid-$t-bc-graql.json
done
for t in $TASKS; do  # the stricter prefix variant
  $GB run -t GRAIL/MiniGrid-$t-v0 -r bc -r graql $SCORERS --protocol prefix --seeds 10 --no-progress --json leaderboard/results/MiniGrid-$t-bc-graql-prefix.json
done
for n in 1 2 3; do  # GAIL/AIRL: fits are shared across goal sets (goal-keyed demos and seeds)
  for t in Optimal-6Goals Optimal-4Goals Optimal Suboptimal-6Goals Suboptimal-4Goals Suboptimal Biased; do
    $GB run -t GRAIL/MiniGrid-$t-v0 -r gail -r airl $SCORERS --seeds $n --no-progress --json leaderboard/results/MiniGrid-$t-gail-airl.json
  done
done
