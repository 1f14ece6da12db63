"""Shared fixtures."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import pytest

import grail_bench
from grail_bench.stats.metrics import Summary, summarize


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
    """A seeded generator."""
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
    "gc-draco": {"ppo_steps": 1024},
    "graml": {"n_pairs": 300, "n_epochs": 3},
    "gc-graml": {"n_pairs": 300, "n_epochs": 3, "gc_batches": 300, "n_rollouts": 3},
    "grnet": {"epochs": 2, "draws": 5},
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


def stored_config(task_id: str, name: str, settings: dict | None = None, drop: str | None = None,
                  task_params: dict | None = None) -> tuple[str, str]:
    """``(config JSON, config hash)`` as planning stores them for recognizer ``name`` built with ``settings``.

    Args:
        task_id: The task, at its defaults unless ``task_params`` gives the parameters the run used.
        drop: A setting the stored configuration lacks (as stored before the setting existed); the hash is then
            that of the configuration without it, as the earlier version computed it.
    """
    import json

    from grail_bench.harness.planning import config_hash, fitted_config
    from grail_bench.recognizers.registry import build
    from grail_bench.task import find_task

    config = fitted_config(find_task(task_id, task_params), name, build(name, settings).config)
    if drop is not None:
        del config["config"][drop]
    return json.dumps(config, sort_keys=True, default=str), config_hash(config)


def offline_record(task_id: str = "GRAIL/MiniGrid-Optimal-v0", name: str = "bc", level: float = 0.1,
                   f1: float | Sequence[float] | Summary = 0.5, *, scorer: str | None = None,
                   settings: dict | None = None, drop: str | None = None, task_params: dict | None = None,
                   **fields: Any) -> Any:
    """An :class:`~grail_bench.harness.modes.offline.OfflineRecord` as aggregating stored rows makes it.

    Its configuration, hash, task parameters and recognizer settings are those of :func:`stored_config`; its
    scorer the recognizer's default and its protocol the task's unless given.

    Args:
        f1: Per-seed values (summarised as the harness does, :func:`grail_bench.stats.metrics.summarize`), a
            ready :class:`~grail_bench.stats.metrics.Summary`, or a mean alone: then two seeds 0.1 either side of
            it, reported with std 0.1 and that interval.
        **fields: Any other record field (``seeds``, ``protocol``, ``config_hash``, ``accuracy_mean``, ...).
    """
    from grail_bench.harness.modes.offline import OfflineRecord
    from grail_bench.harness.planning import recognizer_config
    from grail_bench.harness.planning import task_params as stored_params
    from grail_bench.recognizers.registry import recognizer_info

    if isinstance(f1, (int, float)):
        f1 = Summary(f1, 0.1, (f1 - 0.1, f1 + 0.1), f1, (f1 - 0.1, f1 + 0.1))
    elif not isinstance(f1, Summary):
        f1 = summarize(f1)
    config_json, hashed = stored_config(task_id, name, settings, drop, task_params)
    n = len(f1.values)
    mean = f1.mean
    base = dict(task=task_id, recognizer=name, scorer=scorer or recognizer_info(name).default_scorer,
                protocol=grail_bench.make_task(task_id).protocol_label, config_hash=hashed, n_seeds=n,
                seeds=list(range(n)), fit_seconds_per_goal=1.0, task_params=stored_params(config_json),
                recognizer_config=recognizer_config(config_json), observability=level, f1=f1, accuracy_mean=mean,
                precision_mean=mean, recall_mean=mean, score_us_per_observation=10.0, tie_rate=0.0)
    return OfflineRecord(**(base | fields))
