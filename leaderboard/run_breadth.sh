#!/usr/bin/env bash
# Past the paper (docs/results/breadth.md): gr_libs' MiniGrid
# crossings and PointMaze maps under gr_libs' protocol (both its forms), and the symbolic tasks under missing,
# noisy and actions-only observations; gr_libs' parking lot, its smaller goal sets (L1-L4) and its PandaReach goal
# sets. Run from a worktree at a fixed commit with its own model cache (GRAIL_BENCH_CACHE); it resumes from the
# store where it stops. Parking needs the extra `parking` (installed by `make`).
set -euo pipefail
cd "$(dirname "$0")/.."
bash leaderboard/store.sh  # the store, built from leaderboard/published when missing
.venv/bin/grail-bench reproduce --profile breadth --store leaderboard/results.sqlite --out leaderboard/breadth \
    --workers 2 --no-progress --no-site
# The RL baselines and the later sections were added section by section from worktrees at commits 6300a0e,
# 836951d, c2f4270, cf23443, aad8842, fd16f77, 4dadf1c, 79f7f79, 4c67657, 013729c, 63e8dbf and 8684c23 (each command
# resumes from the store; the tables and figures were then written from it with --no-run):
#   reproduce --profile breadth --only parking-rl-subset --only parking-rl-prefix            (seeds 4-9)
#   reproduce --profile breadth --only crossing-rl-subset --only crossing-rl-prefix -r draco --seeds 3
#   reproduce --profile breadth --only maze-rl-prefix --only maze-rl-subset -r gc-draco --seeds 3
#   reproduce --profile breadth --only panda-grlibs-gc --seeds 1
#   reproduce --profile breadth --only crossing-rl-subset --only crossing-rl-prefix -r draco
#   reproduce --profile breadth --only panda-grlibs-gc --seeds 3                             (aad8842)
#   reproduce --profile breadth --only maze-rl-subset --only maze-rl-prefix -r draco         (fd16f77)
#   reproduce --profile breadth --only maze-rl-subset --only maze-rl-prefix -r gc-draco      (fd16f77)
#   reproduce --profile breadth --only levels-parking --seeds 10                              (4dadf1c)
#   reproduce --profile breadth --only levels-maze --seeds 10                                 (79f7f79)
#   reproduce --profile breadth --only levels-crossing-prefix --seeds 10                      (79f7f79)
#   reproduce --profile breadth --only parking-rl-subset --only parking-rl-prefix -r draco --seeds N
#                                                                    (79f7f79; N = 1, ..., 10: seed by seed)
#   reproduce --profile breadth --only levels-maze-prefix --seeds N                (79f7f79; N = 3, 5, 10)
#   reproduce --profile breadth --only panda-grlibs-gc-prefix                                 (79f7f79)
#   reproduce --profile breadth --only panda-grlibs --only panda-grlibs-prefix --seeds N
#                                                       (4c67657: BC and GRAML, both protocols; N = 5, 7, 10)
#   reproduce --profile breadth --only panda-grlibs-rl --only panda-grlibs-rl-prefix --seeds N
#                                          (013729c: DRACO, both protocols; N = 1, ..., 10: seed by seed)
#   reproduce --profile breadth --only panda-grlibs-rl-clip --only panda-grlibs-rl-clip-prefix (63e8dbf)
#   reproduce --profile breadth --only budget-gc-draco-parking --seeds 2                      (63e8dbf)
#   reproduce --profile breadth --only panda-grlibs-gc --only panda-grlibs-gc-prefix --seeds N
#                                                         (63e8dbf: GC-DRACO, GC-GRAML; N = 4, ..., 10: seed by seed)
#   reproduce --profile breadth --only maze-rl-clip --only maze-rl-clip-prefix                (8684c23)
#   reproduce --profile breadth --only budget-gc-draco-parking                                (8684c23)
#   reproduce --profile breadth --no-run --out leaderboard/breadth
# (each with --store leaderboard/results.sqlite --workers 2 --no-progress --no-site; the running ones with
# --out <a scratch folder>).
