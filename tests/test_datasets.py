"""Demonstrations as Minari datasets: exported, read back, refused when they do not fit the task."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import grail_bench
from grail_bench.harness.api import evaluate
from grail_bench.task.datasets import dataset_id, export, load_demos

BIN = Path(sys.executable).parent
TASK = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v0", turn_prob=0.5)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("datasets")
    return out, export(TASK, [0, 1], out)


def test_one_dataset_per_seed_with_goals_splits_and_the_task(exported):
    import minari

    out, paths = exported
    assert [p.relative_to(out).as_posix() for p in paths] == [dataset_id(TASK, s) for s in (0, 1)]
    assert dataset_id(TASK, 0) == "grail-bench/MiniGrid-Suboptimal-seed0-v0"  # Minari's namespace/name-vN
    dataset = minari.MinariDataset(paths[0] / "data")
    assert dataset.total_episodes == 2 * 10
    labels = list(dataset.storage.get_episode_metadata(range(20)))
    assert [lab["split"] for lab in labels[:10]] == ["train"] * 7 + ["test"] * 3
    assert [tuple(lab["goal"]) for lab in labels[::10]] == [(7.0, 1.0), (7.0, 7.0)]
    meta = json.loads(dataset.storage.metadata["grail_bench"])
    assert meta["task"] == TASK.id and meta["params"]["turn_prob"] == 0.5 and meta["seed"] == 0
    assert meta["protocol"] == "subset" and meta["version"] == grail_bench.__version__
    env = dataset.recover_environment(eval_env=True)  # the GRAIL env, with the task's overrides
    assert env.unwrapped.task.id == TASK.id and env.unwrapped.task.params["turn_prob"] == 0.5


def test_read_back_they_are_the_generators_demonstrations(exported):
    out, _ = exported
    for seed in (0, 1):
        loaded = load_demos(TASK, str(out), seed)  # a folder of datasets: the one of this seed
        assert loaded.seed == seed and (loaded.n_train, loaded.n_demos) == (7, 10)
        for goal, trajs in TASK.generate_demos(seed).items():
            for mine, theirs in zip(loaded.demos[goal], trajs, strict=True):
                assert np.array_equal(mine.obs, theirs.obs) and np.array_equal(mine.acts, theirs.acts)
                assert [i["is_success"] for i in mine.infos] == [i["is_success"] for i in theirs.infos]


def test_a_run_from_the_datasets_gives_the_generators_f1(exported, monkeypatch):
    out, _ = exported
    real_loads = pickle.loads
    monkeypatch.setattr(pickle, "loads", lambda *a, **k: pytest.fail("loading a dataset unpickled something"))
    from_data = evaluate(TASK.id, [("bc", {"n_epochs": 2})], seeds=2, task_params={"turn_prob": 0.5,
                                                                                   "demos": str(out)})
    monkeypatch.setattr(pickle, "loads", real_loads)
    generated = evaluate(TASK.id, [("bc", {"n_epochs": 2})], seeds=2, task_params={"turn_prob": 0.5})
    assert [r.f1_values for r in from_data] == [r.f1_values for r in generated]
    assert from_data[0].config_hash != generated[0].config_hash  # the dataset's content keys its results


def test_datasets_that_do_not_fit_the_task_are_one_line(exported, tmp_path):
    out, paths = exported
    env = {**os.environ, "COLUMNS": "200", "GRAIL_BENCH_STORE": str(tmp_path / "s.sqlite")}

    def run(*args):
        return subprocess.run([str(BIN / "grail-bench"), "run", "-r", "bc", "--seeds", "1", "--no-progress", *args],
                              capture_output=True, text=True, env=env, timeout=600)

    for args, message in (
        (["-t", "GRAIL/PandaReach-Optimal-v0", "--demos", str(paths[0])], "observation space"),
        (["-t", "GRAIL/MiniGrid-Optimal-4Goals-v0", "--demos", str(paths[0])], "needs training and test episodes"),
        (["-t", TASK.id, "--demos", str(tmp_path / "nothing")], "no Minari dataset"),
        (["-t", TASK.id, "--param", "turn_prob=0.5", "--demos", str(out), "--seeds", "3"],
         "no dataset exported with seed 2 (seeds there: [0, 1])"),
    ):
        out_ = run(*args)
        lines = out_.stderr.strip().splitlines()
        assert out_.returncode == 2 and len(lines) == 1 and message in lines[0], out_.stderr
    assert not (tmp_path / "s.sqlite").exists()  # refused before the store was opened, let alone written


def test_episodes_without_goal_labels_are_refused(tmp_path):
    import minari

    (path,) = export(TASK, [0], tmp_path)
    storage = minari.MinariDataset(path / "data").storage
    storage.update_episode_metadata([{"split": "train"}] * storage.total_episodes)  # goals gone
    import h5py

    with h5py.File(path / "data" / "main_data.hdf5", "a") as f:
        for i in range(storage.total_episodes):
            f[f"episode_{i}"].attrs.pop("goal", None)
    with pytest.raises(grail_bench.UserError, match="has no goal label"):
        load_demos(TASK, str(path), 0)
