#!/usr/bin/env bash
# Regenerates LEADERBOARD.md, site/ (the web page), ABLATION.md, ablation.png, ONLINE.md, online.png and
# OPEN_SET.md from the store the run_*.sh scripts fill.
set -euo pipefail
cd "$(dirname "$0")/.."
bash leaderboard/store.sh  # the store, built from leaderboard/published when missing
export GRAIL_BENCH_STORE=leaderboard/results.sqlite COLUMNS=200
GB=".venv/bin/grail-bench"
# Every stored run: the main boards show each method's canonical configuration (today's default under its own
# scorer) and the demonstrator as a reference; every other configuration (another scorer, an off-support rule,
# occupancy, a budget) is a named variant, and runs of superseded configurations are archived.
# --read-only: the committed store is not rewritten by reading it (ceilings stay in the cache folder).
$GB leaderboard --workers "$(nproc)" --read-only \
    --reference grail_bench/paper_reported.csv --markdown leaderboard/LEADERBOARD.md --html leaderboard/site > /dev/null
$GB leaderboard --ablation --plot leaderboard/ablation.png --markdown leaderboard/ABLATION.md > /dev/null
# Beyond the paper (leaderboard/run_online.sh): online recognition and open set.
$GB leaderboard --online --read-only --plot leaderboard/online.png --markdown leaderboard/ONLINE.md > /dev/null
$GB leaderboard --open-set --markdown leaderboard/OPEN_SET.md > /dev/null
# The results as data (docs/guides/results.md): JSON Lines under the schema `grail-bench results schema` prints;
# the same store gives byte-identical files, and new runs add only their lines.
$GB results export --out leaderboard/published > /dev/null
