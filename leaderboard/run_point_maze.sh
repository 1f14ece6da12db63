#!/usr/bin/env bash
# PointMaze runs behind leaderboard/ (see leaderboard/README.md). DRACO trains once per goal and seed and is
# reused by all four tasks (it learns from the reward alone); the imitation learners train per task.
set -euo pipefail
cd "$(dirname "$0")/.."
bash leaderboard/store.sh  # the store, built from leaderboard/published when missing
export GRAIL_BENCH_STORE=leaderboard/results.sqlite
GB=".venv/bin/grail-bench"
TASKS="Optimal Biased Noisy-0.1 Noisy-0.3"
for t in $TASKS; do
  $GB run -t GRAIL/PointMaze-$t-v0 -r bc --seeds 5 --no-progress --json leaderboard/results/PointMaze-$t-bc.json
done
for t in $TASKS; do
  $GB run -t GRAIL/PointMaze-$t-v0 -r draco --seeds 3 --no-progress --json leaderboard/results/PointMaze-$t-draco.json
done
# GAIL and AIRL: about 30 s per goal and seed here (40 000 generator steps).
for t in $TASKS; do
  $GB run -t GRAIL/PointMaze-$t-v0 -r gail -r airl --seeds 2 --no-progress \
      --json leaderboard/results/PointMaze-$t-gail-airl.json
done
# DRACO with four times its default SAC budget (one seed; its models serve all four tasks).
for t in $TASKS; do
  $GB run -t GRAIL/PointMaze-$t-v0 -r draco --set draco.sac_steps=60000 --seeds 1 --no-progress \
      --json leaderboard/results/PointMaze-$t-draco-60k.json
done
$GB run -t GRAIL/PointMaze-Optimal-v0 -r graql --seeds 1 --no-progress || true  # refuses: continuous states
