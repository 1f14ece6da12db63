#!/usr/bin/env bash
# Budget studies (docs/guides/budgets.md), 5 seeds each, into budgets.sqlite; resumes from the
# store where it stops.
# - MiniGrid (budgets/): F1 at 30 % observed against BC's epochs, GRAQL's episodes, GAIL's and AIRL's generator
#   steps and the training demonstrations per goal on the 6-goal tasks.
# - PandaReach (budgets/panda/): F1 at 2 % observed on PandaReach-Aligned-Gaussian-0.3 against DRACO's PPO and
#   SAC steps and BC's training demonstrations per goal (on 2 workers: PPO 1 h 17 min, SAC 1 h 26 min, the
#   demos 33 min).
# - DRACO on MiniGrid (budgets/draco-minigrid/, beyond the paper): F1 at 30 % observed on the 6-goal tasks against
#   its PPO steps (10 min on 2 workers).
set -euo pipefail
cd "$(dirname "$0")/.."
GB=".venv/bin/grail-bench"
$GB reproduce --profile paper --only budget-bc --only budget-graql --only budget-demos \
    --only budget-gail --only budget-airl --workers 2 \
    --store leaderboard/budgets.sqlite --out leaderboard/budgets --no-site --no-progress
$GB reproduce --profile paper --only budget-draco-ppo --only budget-draco-sac --only budget-panda-demos \
    --workers 2 --store leaderboard/budgets.sqlite --out leaderboard/budgets/panda --no-site --no-progress
$GB reproduce --profile paper --only budget-draco-minigrid --workers 2 --store leaderboard/budgets.sqlite \
    --out leaderboard/budgets/draco-minigrid --no-site --no-progress
