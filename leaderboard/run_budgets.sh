#!/usr/bin/env bash
# Budget studies (see the main README's "Training budgets"): F1 at 30 % observed against BC's epochs, GRAQL's
# episodes, GAIL's and AIRL's generator steps and the training demonstrations per goal on the MiniGrid 6-goal
# tasks, 5 seeds, into budgets.sqlite and budgets/. Resumes from the store where it stops. The DRACO and
# PandaReach sections (budget-draco-ppo, budget-draco-sac, budget-panda-demos) are not run here.
set -euo pipefail
cd "$(dirname "$0")/.."
.venv/bin/grail-bench reproduce --profile paper --only budget-bc --only budget-graql --only budget-demos \
    --only budget-gail --only budget-airl --workers 2 \
    --store leaderboard/budgets.sqlite --out leaderboard/budgets --no-site --no-progress
