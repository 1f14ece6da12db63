#!/usr/bin/env bash
# Builds leaderboard/results.sqlite, the store the run_*.sh scripts add to and publish.sh reads, from the
# published results (leaderboard/published, the files in git) when it is missing. publish.sh writes it back.
set -euo pipefail
cd "$(dirname "$0")/.."
test -f leaderboard/results.sqlite ||
    .venv/bin/grail-bench results import leaderboard/published --store leaderboard/results.sqlite
