#!/usr/bin/env bash
# gr_libs 1.0.3 and grail-bench side by side on gr_libs' MiniGrid-SimpleCrossingS13N4 (task L5, 7 goals):
# writes leaderboard/gr_libs/RESULTS.md. Run from anywhere:
#   bash leaderboard/gr_libs/run.sh
# Budgets (environment variables): RUNS gr_libs runs (seeds 0..RUNS-1), SEEDS grail-bench seeds, EPISODES
# gr_libs' Q-learning episodes per goal, LSTM_SAMPLES GRAML's dataset size.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
RUNS="${RUNS:-5}"
SEEDS="${SEEDS:-3}"
EPISODES="${EPISODES:-800}"
LSTM_SAMPLES="${LSTM_SAMPLES:-2000}"
TASK="GRAIL/MiniGrid-SimpleCrossing-Optimal-v0"
LEVELS="0.3,0.5,0.7,0.9,1.0"
GB="$ROOT/.venv/bin/grail-bench"
COMMAND="RUNS=$RUNS SEEDS=$SEEDS EPISODES=$EPISODES LSTM_SAMPLES=$LSTM_SAMPLES bash leaderboard/gr_libs/run.sh"

test -x "$HERE/.venv/bin/python" || bash "$HERE/setup_venv.sh"
test -x "$GB" || { echo "error: $GB not found: run 'make demo' (or the Makefile's set-up) in $ROOT first" >&2; exit 2; }
WORK="$(mktemp -d -t gr_libs_vs_grail.XXXXXX)"
trap 'echo "run files kept in $WORK" >&2' ERR
START=$(date +%s)

# gr_libs on one core: GRAQL then GRAML in each run's own folder (they share its Q-tables, as in gr_libs).
(cd "$WORK" && "$HERE/.venv/bin/python" "$HERE/gr_libs_side.py" --recognizer Graql --recognizer ExpertBasedGraml \
    --task L5 --runs "$RUNS" --episodes "$EPISODES" --lstm-samples "$LSTM_SAMPLES" --out "$WORK/gr_libs.json" \
    2> "$WORK/gr_libs.stderr") &
GR_PID=$!

# grail-bench on the other: a temporary store and model cache; the subset run reuses the prefix run's fits.
for protocol in prefix subset; do
    GRAIL_BENCH_CACHE="$WORK/cache" "$GB" run -t "$TASK" -r graql -r bc --seeds "$SEEDS" -o "$LEVELS" \
        --protocol "$protocol" --rounding floor --store "$WORK/store.sqlite" --no-progress > "$WORK/grail_$protocol.log"
    echo "grail-bench: $protocol done"
done
if ! wait "$GR_PID"; then
    grep -v -i "warn\|registration" "$WORK/gr_libs.stderr" | tail -20 >&2
    exit 1
fi

"$ROOT/.venv/bin/python" "$HERE/report.py" --gr-libs "$WORK/gr_libs.json" --store "$WORK/store.sqlite" \
    --task "$TASK" --command "$COMMAND" --seconds "$(( $(date +%s) - START ))" --out "$HERE/RESULTS.md"
cp "$WORK/gr_libs.json" "$HERE/gr_libs_records.json"  # every gr_libs instance, for auditing RESULTS.md
rm -rf "$WORK"
echo "wrote $HERE/RESULTS.md"
