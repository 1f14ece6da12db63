#!/usr/bin/env bash
# Many goals (see leaderboard/README.md): F1 and fit cost against the goal count (2 to 24 MiniGrid goals; BC,
# GC-BC, GRAQL), and zero-shot goals (GC-BC scoring goals it was never fitted on), into goals.sqlite and goals/.
# Resumes from the store where it stops. The adversarial scaling section (scaling-goals-adversarial) is not run here.
set -euo pipefail
cd "$(dirname "$0")/.."
.venv/bin/grail-bench reproduce --profile paper --only scaling-goals --only zero-shot --workers 2 \
    --store leaderboard/goals.sqlite --out leaderboard/goals --no-site --no-progress
