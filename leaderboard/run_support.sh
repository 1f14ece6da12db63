#!/usr/bin/env bash
# Where the per-goal policies have evidence (leaderboard/README.md, "Where the policies have evidence"): the
# support profile on MiniGrid's paper grid (off-support rules, BC with stay pairs, the occupancy scorer, the
# demonstrator), then the paper profile's MiniGrid, online and open-set sections, which recompute the stored rows
# that tied under the earlier tie rule and add online and open-set rows at today's defaults (their models come
# from the support run's cache). Published from a worktree at commit 2db7bbd; resumes from the store.
set -euo pipefail
cd "$(dirname "$0")/.."
GB=".venv/bin/grail-bench"
S=leaderboard/results.sqlite
$GB reproduce --profile support --store $S --out leaderboard/support --workers 2 --no-progress --no-site
$GB reproduce --profile paper --only minigrid --store $S --out leaderboard/paper --workers 2 --no-progress --no-site
$GB reproduce --profile paper --only online --only open-set --store $S --out /tmp/grail-bench-online --workers 2 \
    --no-progress --no-site
leaderboard/publish.sh
