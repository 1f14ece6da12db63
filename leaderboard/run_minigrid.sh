#!/usr/bin/env bash
# MiniGrid runs behind leaderboard/ (see leaderboard/README.md). Both steps resume from the store where they stop.
set -euo pipefail
cd "$(dirname "$0")/.."
bash leaderboard/store.sh  # the store, built from leaderboard/published when missing
GB=".venv/bin/grail-bench"
# The paper's grid: every MiniGrid task under its default protocol and rounding (subset; biased: prefix;
# k = ceil(p*T)), BC, GRAQL, GAIL and AIRL, 10 seeds, the four scorers; also writes leaderboard/paper/ (tables
# with CIs, figures, manifest; the one published web page is leaderboard/site/, written by publish.sh from the
# whole store).
$GB reproduce --profile paper --only minigrid --workers 2 --store leaderboard/results.sqlite --out leaderboard/paper --no-site \
    --no-progress
# Beyond the paper, which runs DRACO on PandaReach only: DRACO on the same tasks (one PPO agent per goal, shared
# by the regimes), for MiniGrid's summary; its rows reach the boards through publish.sh, its tables go to a scratch
# folder (run from a worktree at 8684c23: 70 units in 304 s on 2 workers, 60 agents trained).
$GB reproduce --profile paper --only minigrid-draco --workers 2 --store leaderboard/results.sqlite \
    --out /tmp/paper-minigrid-draco --no-site --no-progress
# The stricter prefix variant, BC and GRAQL (published with ceil rounding).
SCORERS="--scorer mse --scorer kl --scorer wasserstein --scorer loglik"
for t in Optimal Optimal-4Goals Optimal-6Goals Suboptimal Suboptimal-4Goals Suboptimal-6Goals Biased; do
  $GB run -t GRAIL/MiniGrid-$t-v0 -r bc -r graql $SCORERS --protocol prefix --rounding ceil --seeds 10 --workers 2 --no-progress \
      --store leaderboard/results.sqlite --json leaderboard/results/MiniGrid-$t-bc-graql-prefix.json
done
# The same grid with the other rounding (floor: gr_libs' int(p*T), at least 1; the paper does not say how it
# rounds, see docs/results/minigrid.md, "Rounding"). Every model comes from the cache of the run above.
for t in Optimal Optimal-4Goals Optimal-6Goals Suboptimal Suboptimal-4Goals Suboptimal-6Goals; do
  $GB run -t GRAIL/MiniGrid-$t-v0 -r bc -r graql -r gail -r airl $SCORERS --rounding floor --seeds 10 --workers 2 \
      --no-progress --store leaderboard/results.sqlite
done
