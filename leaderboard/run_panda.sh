#!/usr/bin/env bash
# PandaReach runs behind leaderboard/ (see leaderboard/README.md), both goal sets, 2 seeds: BC-GRAIL (at the 25
# epochs it was run with), DRACO with PPO (its default, as the paper states) and DRACO with SAC (a named
# configuration). DRACO's models depend only on the goal and seed, so the five regimes of a goal set share them.
set -euo pipefail
cd "$(dirname "$0")/.."
bash leaderboard/store.sh  # the store, built from leaderboard/published when missing
export GRAIL_BENCH_STORE=leaderboard/results.sqlite
GB=".venv/bin/grail-bench"
SCORERS="--scorer mse --scorer wasserstein --scorer loglik"
for t in Optimal Gaussian-0.1 Gaussian-0.3 Uniform-0.1 Uniform-0.3 Aligned-Optimal Aligned-Gaussian-0.1 \
         Aligned-Gaussian-0.3 Aligned-Uniform-0.1 Aligned-Uniform-0.3; do
  $GB run -t GRAIL/PandaReach-$t-v0 -r bc --set bc.n_epochs=25 $SCORERS --seeds 2 --workers 2 --no-progress \
      --json leaderboard/results/PandaReach-$t-bc.json
  $GB run -t GRAIL/PandaReach-$t-v0 -r draco $SCORERS --seeds 2 --workers 2 --no-progress \
      --json leaderboard/results/PandaReach-$t-draco-ppo.json
  $GB run -t GRAIL/PandaReach-$t-v0 -r draco --set draco.algorithm=sac $SCORERS --seeds 2 --workers 2 --no-progress \
      --json leaderboard/results/PandaReach-$t-draco-sac.json
done

# The paper profile's PandaReach sections at the paper's scale: BC and DRACO (both
# algorithms) at 10 seeds, GAIL and AIRL at 3. Each skips the units the store holds, so the script resumes.
for args in "-r bc" "-r gail -r airl --seeds 3" "--only panda-sac -r draco"; do
  # shellcheck disable=SC2086  # $args is several options
  $GB reproduce --profile paper --only panda $args --workers "$(nproc)" --store "$GRAIL_BENCH_STORE" \
      --out /tmp/panda-paper --no-site --no-progress
done
