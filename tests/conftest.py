"""Shared fixtures."""

from __future__ import annotations

import numpy as np
import pytest

import grail_bench


def chmod_stops_writes() -> bool:
    """Whether a file without write permission refuses this process (not so for root, with its capabilities)."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        probe = Path(folder) / "probe"
        probe.write_text("")
        probe.chmod(0o444)
        try:
            probe.open("a").close()
        except PermissionError:
            return True
        return False


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator, as imitation's tests use."""
    return np.random.default_rng(0)


@pytest.fixture(scope="session")
def all_task_ids() -> list[str]:
    return grail_bench.task_ids()


PLUGIN_DIR = __import__("pathlib").Path(__file__).parent / "plugin"


def install_plugin(root, name: str = "toy", target: str = "toy_recognizer:LookupRecognizer"):
    """Make a minimal installed distribution under ``root`` declaring one recognizer entry point.

    Returns:
        The folder to put on ``sys.path`` / ``PYTHONPATH``.
    """
    import shutil

    root.mkdir(parents=True, exist_ok=True)
    for module in ("toy_recognizer.py", "minimal_recognizer.py"):
        shutil.copy(PLUGIN_DIR / module, root / module)
    dist = root / f"toy_plugin_{root.name}-0.1.dist-info"
    dist.mkdir(exist_ok=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: toy-plugin-{root.name}\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[grail_bench.recognizers]\n{name} = {target}\n")
    return root


@pytest.fixture
def toy_plugin(tmp_path, monkeypatch):
    """The toy recognizer installed as a plugin for this test (entry point ``toy``)."""
    root = install_plugin(tmp_path / "site")
    monkeypatch.syspath_prepend(str(root))
    import importlib

    importlib.invalidate_caches()
    return root


FAST = {
    "bc": {"n_epochs": 3},
    "graql": {"episodes": 200},
    "gail": {"total_timesteps": 512, "n_envs": 4, "n_steps": 64, "n_epochs": 2},
    "airl": {"total_timesteps": 512, "n_envs": 4, "n_steps": 64, "n_epochs": 2},
    "draco": {"ppo_steps": 1024},
}


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    """Trained-model caches go to a per-session folder, never the user's."""
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))


def run_mode(mode, task, planned, seed, levels, protocol, demos=None, rounding="ceil"):
    """One seed of a mode's run, as a sweep unit runs it: ``(rows, fit report)``."""
    from grail_bench.harness.modes import MODES, SeedRun
    from grail_bench.task.observation import ObservationSpec

    job = SeedRun(task=task, planned=planned, seed=seed, observation=ObservationSpec.resolve(protocol, rounding, levels),
                  versions="{}", demos=demos if demos is not None else task.generate_demos(seed))
    return MODES[mode].run(job)
