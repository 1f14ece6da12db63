#!/usr/bin/env bash
# Where the per-goal policies have evidence (docs/results/support.md).
# MiniGrid: the support profile's MiniGrid sections (off-support rules, BC with stay pairs, the occupancy scorer,
# the demonstrator), then the paper profile's MiniGrid, online and open-set sections, which recompute the stored
# rows that tied under the earlier tie rule and add online and open-set rows at today's defaults (their models
# come from the support run's cache). Published from a worktree at commit 2db7bbd.
# PointMaze and PandaReach: the profile's maze-* and panda-* sections, BC and the demonstrator at 10 seeds,
# GAIL, AIRL and DRACO at 2 (from a worktree at commit 9c9b5bf). Every command resumes from the store.
set -euo pipefail
cd "$(dirname "$0")/.."
bash leaderboard/store.sh  # the store, built from leaderboard/published when missing
GB=".venv/bin/grail-bench"
S=leaderboard/results.sqlite
RUN="$GB reproduce --profile support --store $S --workers 2 --no-progress --no-site"
MINIGRID="--only support-trust --only support-stay --only support-uniform --only support-augment
          --only demonstrator-everywhere --only demonstrator-demonstrated"
MAZE="--only maze-trust --only maze-stay --only maze-uniform --only maze-augment"
PANDA="--only panda-trust --only panda-stay --only panda-uniform --only panda-augment"
# shellcheck disable=SC2086  # the section lists are several options
{
  $RUN $MINIGRID --out leaderboard/support
  $GB reproduce --profile paper --only minigrid --store $S --out leaderboard/paper --workers 2 --no-progress --no-site
  $GB reproduce --profile paper --only online --only open-set --store $S --out /tmp/grail-bench-online --workers 2 \
      --no-progress --no-site
  $RUN $MAZE --only maze-demonstrator-everywhere --only maze-demonstrator-demonstrated -r bc -r demonstrator \
      --out leaderboard/support/maze-bc
  $RUN $MAZE -r gail -r airl -r draco --seeds 2 --out leaderboard/support/maze-rl
  for t in Optimal Biased Noisy-0.1 Noisy-0.3; do  # DRACO under its own scorer, from the same models
    $GB run -t GRAIL/PointMaze-$t-v0 -r draco --scorer wasserstein --seeds 2 --workers 2 --no-progress --store $S
  done
  # DRACO to 10 seeds, from a worktree at commit fd16f77 (its PPO update in numpy on continuous actions)
  $RUN $MAZE -r draco --out /tmp/support-maze-draco
  for t in Optimal Biased Noisy-0.1 Noisy-0.3; do
    $GB run -t GRAIL/PointMaze-$t-v0 -r draco --scorer wasserstein --seeds 10 --workers 2 --no-progress --store $S
  done
  $RUN $PANDA -r bc --seeds 2 --out /tmp/support-panda
  # BC at its paper scale under the variants, 10 seeds, from worktrees at commits 9c9b5bf, ecbbad2 and 77636ff
  # (seeds 0-3), 6c04e07 (4-8, one `--seeds N` at a time) and 4dadf1c (9); it resumes from the store.
  $RUN $PANDA -r bc --out leaderboard/support/panda-bc
  # DRACO and GAIL under the variants, 3 seeds (DRACO from a worktree at commit de0c254, the rest at 4c67657, which
  # lists GAIL and AIRL in the PandaReach sections and adds action_box; both retrain their models: the cache keys of
  # continuous PPO carry the numpy update), and their means clipped to the action box (scoring only, the same
  # models).
  CLIP="--only panda-clip --only panda-clip-stay"
  $RUN $PANDA -r draco --seeds 3 --out /tmp/support-panda-draco
  $RUN $CLIP -r draco --seeds 3 --out /tmp/support-panda-clip
  $RUN $PANDA -r gail --seeds 3 --out /tmp/support-panda-gail    # --seeds 2, then 3
  $RUN $CLIP -r gail --seeds 3 --out /tmp/support-panda-clip     # --seeds 2, then 3
  # DRACO to 10 seeds and AIRL at 3, with the clipped means, one seed at a time from a worktree at commit c02f4e2
  # (DRACO's seed 3, then AIRL's three, then DRACO's seeds 4-9; AIRL retrains its generators for the same reason).
  for n in 4 5 6 7 8 9 10; do $RUN $PANDA $CLIP -r draco --seeds $n --out /tmp/support-panda-draco; done
  for n in 1 2 3; do $RUN $PANDA $CLIP -r airl --seeds $n --out /tmp/support-panda-airl; done
  $GB reproduce --profile support $PANDA $CLIP --no-run --store $S --no-progress --no-site \
      --out leaderboard/support/panda-rl
}
leaderboard/publish.sh
