#!/usr/bin/env bash
# The open questions (issue 62; docs/concepts/shifts.md): `reproduce --profile open-questions`, the paper grid's
# MiniGrid tasks under action slips, in rooms with moved walls and across regimes (with the Boltzmann tasks),
# PointMaze under a weaker actuator; the paper's methods, the support-aware variants, bip, grnet and the
# demonstrator; 10 seeds.
#
#   leaderboard/run_open_questions.sh [COMMIT] [WORKERS] [REPRODUCE OPTIONS...]
#
# COMMIT (default: this checkout's HEAD) is checked out as a detached worktree at /tmp/grail-bench-openq-<commit>
# and the run starts there in the background, with its own model cache (GRAIL_BENCH_CACHE, default the worktree's
# .cache: every shift level and off-support rule reuses the task's models from it), WORKERS parallel units
# (default 2), into this checkout's store leaderboard/results.sqlite; tables, figures and the manifest go to
# leaderboard/open-questions/, the log and the process id beside them (run.log, run.pid). It resumes from the store
# where it stops: run it again with the same commit. Further arguments go to `reproduce` (e.g. --add-outputs, with
# GRAIL_BENCH_CACHE set to an earlier commit's cache). Planned: 12 930 units (tests/test_sweep.py); see
# leaderboard/README.md, "To be published", for the expected time. Start it on a quiet machine only.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
COMMIT=$(git rev-parse --short "${1:-HEAD}")
WORKERS=${2:-2}
shift $(( $# < 2 ? $# : 2 ))
WT=/tmp/grail-bench-openq-$COMMIT
OUT=$ROOT/leaderboard/open-questions
PY=$ROOT/.venv/bin/python
if [ -f "$OUT/run.pid" ] && kill -0 "$(cat "$OUT/run.pid")" 2> /dev/null; then
  echo "a run is going on already (process $(cat "$OUT/run.pid"); log $OUT/run.log)" >&2
  exit 2
fi
bash leaderboard/store.sh  # the store, built from leaderboard/published when missing
test -d "$WT" || git worktree add --detach "$WT" "$COMMIT"
# The installed package reads its cards from the checkout it was installed from: the run is COMMIT's only if they
# are COMMIT's cards.
CARDS=$(cd /tmp && PYTHONPATH=$WT "$PY" -c 'from importlib.resources import files; print(files("grail_bench.tasks"))')
if ! diff -rq -x __pycache__ "$WT/tasks" "$CARDS" > /dev/null; then
  echo "the installed cards ($CARDS) differ from those of $COMMIT; install grail-bench from a checkout of it" >&2
  exit 2
fi
mkdir -p "$OUT"
cd "$WT"
export PYTHONPATH=$WT GRAIL_BENCH_CACHE=${GRAIL_BENCH_CACHE:-$WT/.cache}
nohup "$PY" -m grail_bench reproduce --profile open-questions --store "$ROOT/leaderboard/results.sqlite" \
    --out "$OUT" --workers "$WORKERS" --no-progress --no-site "$@" >> "$OUT/run.log" 2>&1 &
echo $! > "$OUT/run.pid"
echo "started commit $COMMIT in $WT as process $! ($WORKERS workers); log: $OUT/run.log"
