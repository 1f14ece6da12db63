#!/usr/bin/env bash
# Past the paper (leaderboard/README.md, "gr_libs' problems" and "Symbolic goal recognition"): gr_libs' MiniGrid
# crossings and PointMaze maps under gr_libs' protocol (both its forms), and the symbolic tasks under missing,
# noisy and actions-only observations; gr_libs' parking lot, its smaller goal sets (L1-L4) and its PandaReach goal
# sets. Run from a worktree at a fixed commit with its own model cache (GRAIL_BENCH_CACHE); it resumes from the
# store where it stops. Parking needs the extra `parking` (installed by `make`).
set -euo pipefail
cd "$(dirname "$0")/.."
.venv/bin/grail-bench reproduce --profile breadth --store leaderboard/results.sqlite --out leaderboard/breadth \
    --workers 2 --no-progress --no-site
