#!/usr/bin/env bash
# Creates leaderboard/gr_libs/.venv with gr_libs 1.0.3 (MiniGrid extra) from the package registry.
# torch 2.13.0 goes first so pip keeps its CPU wheel (a looser requirement pulls the CUDA build);
# everything else comes pinned from requirements.txt, itself produced by `--freeze` from what installed.
#   bash leaderboard/gr_libs/setup_venv.sh            # install from requirements.txt
#   bash leaderboard/gr_libs/setup_venv.sh --freeze   # resolve gr_libs[minigrid]==1.0.3 afresh, rewrite requirements.txt
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="$HERE/.venv"
PY="$VENV/bin/python"
PYTHON="${PYTHON:-python3.11}"

test -x "$PY" || "$PYTHON" -m venv "$VENV"
"$PY" -m pip install --quiet torch==2.13.0
if [[ "${1:-}" == "--freeze" ]]; then
    # torch stays at the installed CPU build while the resolver picks the rest.
    "$PY" -m pip install --quiet "gr_libs[minigrid]==1.0.3" "torch==2.13.0"
    {
        echo "# gr_libs 1.0.3 with its MiniGrid extra, as installed by setup_venv.sh --freeze (Python 3.11)."
        echo "# torch is installed first (torch==2.13.0, the CPU wheel); no nvidia-* package belongs here."
        "$PY" -m pip freeze --exclude-editable | sed -e 's/^torch==\(.*\)+cpu$/torch==\1/'
    } > "$HERE/requirements.txt"
else
    "$PY" -m pip install --quiet -r "$HERE/requirements.txt"
fi
"$PY" -m pip check
if "$PY" -m pip freeze | grep -qi '^nvidia-'; then
    echo "error: a CUDA package was installed into $VENV" >&2
    exit 1
fi
"$PY" -c "import torch; assert not torch.version.cuda, torch.version.cuda; import gr_libs, minigrid; print('gr_libs venv ready: torch', torch.__version__)"
