"""grail-bench installs beside a researcher's own gymnasium and Stable-Baselines3 without moving them."""

from __future__ import annotations

import shutil
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# Versions a researcher's project might hold: inside grail-bench's ranges, other than its lock's.
THEIRS = {"gymnasium": "1.2.2", "stable-baselines3": "2.7.0"}
MAKE = {
    "module-prefix": "import gymnasium as gym\nenv = gym.make('grail_bench:GRAIL/MiniGrid-Biased-v0')",
    "import": "import gymnasium as gym, grail_bench\nenv = gym.make('GRAIL/MiniGrid-Biased-v0')",
    "register_envs": "import gymnasium as gym, grail_bench\ngym.register_envs(grail_bench)\n"
                     "env = gym.make('GRAIL/MiniGrid-Biased-v0')",
}


def _run(*command: object, cwd: Path) -> subprocess.CompletedProcess:
    # Away from the checkout, whose grail_bench/ would shadow the installed package.
    out = subprocess.run([str(c) for c in command], capture_output=True, text=True, timeout=900, cwd=cwd)
    assert out.returncode == 0, f"{command}: {out.stderr[-2000:]}"
    return out


@pytest.mark.slow
def test_pip_install_keeps_the_researchers_gymnasium_and_sb3(tmp_path):
    # The package's own files only, so the build writes nothing into the checkout.
    source = tmp_path / "grail-bench"
    source.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, source)
    for name in ("grail_bench", "tasks"):
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    venv = tmp_path / "venv"
    _run(sys.executable, "-m", "venv", venv, cwd=tmp_path)
    python = venv / "bin" / "python"
    install = [python, "-m", "pip", "install", "--quiet"]
    _run(*install, f"torch=={version('torch').split('+')[0]}", cwd=tmp_path)  # the CPU build first, as make does
    _run(*install, *(f"{name}=={v}" for name, v in THEIRS.items()), cwd=tmp_path)
    _run(*install, source, cwd=tmp_path)
    _run(python, "-m", "pip", "check", cwd=tmp_path)
    installed = _run(python, "-c", "from importlib.metadata import version\n"
                     f"print(' '.join(version(n) for n in {list(THEIRS)!r}))", cwd=tmp_path).stdout.split()
    assert installed == list(THEIRS.values())
    silent = subprocess.run([python, "-c", "import gymnasium"], capture_output=True, text=True, timeout=120,
                            cwd=tmp_path)
    assert (silent.returncode, silent.stdout, silent.stderr) == (0, "", "")
    for form, code in MAKE.items():
        out = _run(python, "-c", f"{code}\nassert env.unwrapped.task.goals == ((7, 1), (7, 7))\nprint('ok')",
                   cwd=tmp_path)
        assert (out.stdout, out.stderr) == ("ok\n", ""), form
