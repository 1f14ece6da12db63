#!/usr/bin/env bash
# Online and open-set runs behind leaderboard/ONLINE.md, online.png and OPEN_SET.md (see leaderboard/README.md).
# Every recognizer at its defaults, as in the paper profile, so with the same model cache (GRAIL_BENCH_CACHE)
# the models of run_minigrid.sh are reused. Both loops resume from the store where they stop. The same units as
# `grail-bench reproduce --profile paper --only online --only open-set`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash leaderboard/store.sh  # the store, built from leaderboard/published when missing
GB=".venv/bin/grail-bench"
RECOGNIZERS="-r bc -r graql -r gail -r airl"
# MiniGrid at ceil rounding (the cards' default, spelled out).
# Online: every prefix of every test trajectory, each recognizer's own scorer, 10 seeds.
for t in Optimal Optimal-4Goals Optimal-6Goals Suboptimal Suboptimal-4Goals Suboptimal-6Goals Biased; do
  $GB run -t GRAIL/MiniGrid-$t-v0 $RECOGNIZERS --online --rounding ceil --seeds 10 --workers 2 --no-progress \
      --store leaderboard/results.sqlite --json leaderboard/results/MiniGrid-$t-online.json
done
# Open set: one goal held out per seed (each in turn), the tasks with 4 and 6 goals, their default levels.
for t in Optimal-4Goals Optimal-6Goals Suboptimal-4Goals Suboptimal-6Goals; do
  $GB run -t GRAIL/MiniGrid-$t-v0 $RECOGNIZERS --open-set --rounding ceil --seeds 10 --workers 2 --no-progress \
      --store leaderboard/results.sqlite --json leaderboard/results/MiniGrid-$t-open-set.json
done
# PointMaze (gymnasium-robotics), both modes: each method with the seeds of its offline runs in run_point_maze.sh,
# so the same cache's models serve (BC 5, DRACO 3, GAIL and AIRL 2 seeds; 5 goals, so open set holds out
# goals 0-4, 0-2 and 0-1 respectively).
for t in Optimal Biased Noisy-0.1 Noisy-0.3; do
  for mode in online open-set; do
    $GB run -t GRAIL/PointMaze-$t-v0 -r bc --seeds 5 --$mode --workers 2 --no-progress \
        --store leaderboard/results.sqlite --json leaderboard/results/PointMaze-$t-$mode-bc.json
    $GB run -t GRAIL/PointMaze-$t-v0 -r draco --seeds 3 --$mode --workers 2 --no-progress \
        --store leaderboard/results.sqlite --json leaderboard/results/PointMaze-$t-$mode-draco.json
    $GB run -t GRAIL/PointMaze-$t-v0 -r gail -r airl --seeds 2 --$mode --workers 2 --no-progress \
        --store leaderboard/results.sqlite --json leaderboard/results/PointMaze-$t-$mode-gail-airl.json
  done
done
