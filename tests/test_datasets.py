"""Demonstrations as Minari datasets: exported, read back, refused when they do not fit the task."""

from __future__ import annotations

import hashlib
import json
import pickle
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

import grail_bench
from grail_bench.cli import app
from grail_bench.harness.api import evaluate
from grail_bench.harness.store import ResultsStore
from grail_bench.task import export as export_module
from grail_bench.task.datasets import load_demos
from grail_bench.task.export import dataset_id, export

TASK = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1", turn_prob=0.5)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("datasets")
    return out, export(TASK, [0, 1], out)


def copy_of(path: Path, where: Path) -> Path:
    """A copy of one exported dataset, to tamper with."""
    return Path(shutil.copytree(path, where))


def without_metadata(path: Path) -> Path:
    """``path`` with its grail_bench metadata removed: a dataset as one recorded elsewhere has it."""
    meta_file = path / "data" / "metadata.json"
    meta = json.loads(meta_file.read_text())
    del meta["grail_bench"]
    meta_file.write_text(json.dumps(meta))
    return path


def with_metadata(path: Path, **changes) -> Path:
    """``path`` with fields of its grail_bench metadata changed."""
    meta_file = path / "data" / "metadata.json"
    meta = json.loads(meta_file.read_text())
    meta["grail_bench"] = json.dumps({**json.loads(meta["grail_bench"]), **changes})
    meta_file.write_text(json.dumps(meta))
    return path


def with_episode(path: Path, episode: int, key: str, step: int, value) -> Path:
    """``path`` with one step of one episode's observations or actions overwritten."""
    with h5py.File(path / "data" / "main_data.hdf5", "a") as f:
        f[f"episode_{episode}"][key][step] = value
    return path


def cli(*args: str):
    return CliRunner().invoke(app, list(args), env={"COLUMNS": "200"})


def one_error_line(result, message: str) -> None:
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and message in lines[0], result.stderr


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


def test_a_task_with_a_dataset_round_trips_its_overrides(exported):
    out, _ = exported
    base = grail_bench.make_task(TASK.id)
    task = grail_bench.make_task(TASK.id, turn_prob=0.5, demos=str(out))
    assert (task.demos, task.n_train, task.n_demos) == (str(out), 7, 10)
    assert task.overrides_against(base).as_dict() == {"demos": str(out), "turn_prob": 0.5}
    assert base.with_overrides(**task.overrides_against(base).as_dict()) == task
    # Counts are the dataset's: another one given beside it is refused, the same one accepted.
    assert grail_bench.make_task(TASK.id, turn_prob=0.5, demos=str(out), n_train=7) == task
    with pytest.raises(grail_bench.UserError, match="n_train=5, but the dataset .* gives 7"):
        grail_bench.make_task(TASK.id, turn_prob=0.5, demos=str(out), n_train=5)


def test_a_run_from_the_datasets_gives_the_generators_f1(exported, monkeypatch):
    out, _ = exported
    real_loads = pickle.loads
    monkeypatch.setattr(pickle, "loads", lambda *a, **k: pytest.fail("loading a dataset unpickled something"))
    from_data = evaluate(TASK.id, [("bc", {"n_epochs": 2})], seeds=2, task_params={"turn_prob": 0.5,
                                                                                   "demos": str(out)})
    monkeypatch.setattr(pickle, "loads", real_loads)
    generated = evaluate(TASK.id, [("bc", {"n_epochs": 2})], seeds=2, task_params={"turn_prob": 0.5})
    assert [r.f1.values for r in from_data] == [r.f1.values for r in generated]
    assert from_data[0].config_hash != generated[0].config_hash  # the dataset's content keys its results


def direct_rollout(env, seed: int, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Observations, rewards, terminations and truncations of ``actions`` played in ``env`` from ``reset(seed)``."""
    obs, _ = env.reset(seed=seed)
    observations, rewards, terminations, truncations = [obs], [], [], []
    for action in actions:
        obs, reward, terminated, truncated, _ = env.step(action)
        observations.append(obs)
        rewards.append(reward)
        terminations.append(terminated)
        truncations.append(truncated)
    return np.stack(observations), np.array(rewards), np.array(terminations), np.array(truncations)


def episodes_with_metadata(path: Path) -> list[tuple[dict, object]]:
    import minari

    dataset = minari.MinariDataset(path / "data")
    return list(zip(dataset.storage.get_episode_metadata(dataset.episode_indices), dataset, strict=True))


@pytest.fixture(scope="module")
def symbolic_export(tmp_path_factory):
    """A task whose episodes end at the goal (the env terminates there), exported."""
    task = grail_bench.make_task("GRAIL/Symbolic-Blocks-Optimal-v0", n_demos=3, n_train=2)
    return task, export(task, [0], tmp_path_factory.mktemp("symbolic"))[0]


@pytest.fixture(scope="module")
def continuous_export(tmp_path_factory):
    """A task with continuous states and actions and a dense reward (pybullet), exported."""
    task = grail_bench.make_task("GRAIL/PandaReach-Gaussian-0.1-v0", expert="scripted", n_demos=2, n_train=1)
    return task, export(task, [0], tmp_path_factory.mktemp("panda"))[0]


def test_an_exports_rewards_and_flags_are_those_of_a_direct_rollout(exported, symbolic_export, continuous_export):
    _, paths = exported
    assert continuous_export[1].name == "PandaReach-Gaussian-0_1-seed0-v0"  # a name Minari takes
    for task, path in ((TASK, paths[0]), symbolic_export, continuous_export):
        episodes = episodes_with_metadata(path)
        assert len(episodes) == len(task.goals) * task.n_demos
        for meta, episode in episodes:
            env = task.make_env(tuple(meta["goal"]))
            obs, rewards, terminations, truncations = direct_rollout(env, meta["seed"], episode.actions)
            env.close()
            assert np.array_equal(obs, episode.observations)
            assert np.array_equal(rewards, episode.rewards) and rewards.dtype == episode.rewards.dtype
            assert np.array_equal(terminations, episode.terminations)
            assert np.array_equal(truncations, episode.truncations)
            assert episode.rewards.any()  # the goal's reward, not the zeros an export once wrote
        assert task.with_overrides(demos=str(path)).n_demos == task.n_demos  # and the task reads it back
    _, finished = episodes_with_metadata(symbolic_export[1])[0]
    assert finished.terminations[-1] and not finished.truncations.any()  # the env ends at the goal
    _, padded = episodes_with_metadata(paths[0])[0]
    assert padded.truncations[-1] and not padded.terminations.any()  # a fixed horizon: cut by the time limit


def test_the_steps_after_the_goal_are_marked_in_the_infos(exported):
    from grail_bench.domains.minigrid.grid import STAY

    _, paths = exported
    labels = set()
    for meta, episode in episodes_with_metadata(paths[0]):
        labels.add((meta["regime"], int(meta["demo_seed"]), meta["seed"]))
        n = int(meta["goal_steps"])
        success = episode.infos["is_success"][1:]  # one info per action after the reset's
        assert success[n - 1] and not success[: n - 1].any()  # the n-th action reached the goal
        after = episode.infos["after_goal"]
        assert len(after) == len(episode.actions) + 1 and not after[0]
        assert np.array_equal(after[1:], np.arange(len(episode.actions)) >= n)
        assert (episode.actions[after[1:]] == STAY).all() and not episode.rewards[after[1:]].any()
        assert (episode.observations[n:] == episode.observations[n]).all()  # the agent stays on the goal
    assert labels == {("suboptimal", 0, 0)}
    stays = sum(episode.infos["after_goal"].sum() for _, episode in episodes_with_metadata(paths[0]))
    assert stays > 0  # the padding is exported, and marked


def test_a_demonstration_that_does_not_replay_is_refused_in_one_line():
    from grail_bench.core.trajectory import Trajectory

    goal = TASK.goals[0]
    [demo] = TASK.generate_demos(0, n_demos=1)[goal]
    obs = demo.obs.copy()
    obs[3, 2] = (obs[3, 2] + 1) % 4  # another heading than the env gives after these actions
    moved = Trajectory(obs=obs, acts=demo.acts, infos=demo.infos)
    with pytest.raises(grail_bench.UserError, match=r"goal \[7, 1\]: replaying the trajectory gives another "
                                                    "observation at step 3") as info:
        export_module._emitted(TASK, [(goal, "train", demo), (goal, "test", moved)])
    assert "\n" not in str(info.value)


def test_an_export_into_minaris_folder_loads_by_its_id(tmp_path, monkeypatch):
    import minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    task = grail_bench.make_task("GRAIL/MiniGrid-Biased-v0")
    [path] = export(task, 1)
    assert path == tmp_path / "minari" / dataset_id(task, 0)
    dataset = minari.load_dataset(dataset_id(task, 0))
    assert dataset.total_episodes == 2 * task.n_demos
    assert load_demos(task, dataset_id(task, 0), 0).n_train == task.n_train  # a biased task reads its own export
    assert grail_bench.make_task(task.id, demos=str(tmp_path / "minari")).n_demos == task.n_demos
    one_error_line(cli("export", "-t", task.id), f"{path} exists already")  # the command's default folder too


def test_an_export_written_before_rewards_and_marks_still_reads(exported, tmp_path):
    _, paths = exported
    path = copy_of(paths[0], tmp_path / "d")
    with h5py.File(path / "data" / "main_data.hdf5", "a") as f:  # what exports wrote before: no marks, zeros
        for name, group in f.items():
            if name.startswith("episode_"):
                del group["infos"]["after_goal"]
                group["rewards"][...] = 0.0
                group["terminations"][...] = False
                for key in ("regime", "demo_seed", "goal_steps", "seed"):
                    group.attrs.pop(key, None)
    old = load_demos(TASK, str(path), 0)
    new = load_demos(TASK, str(paths[0]), 0)
    for goal in TASK.goals:
        assert old.demos[goal] == new.demos[goal]


@pytest.mark.parametrize("task_id, params, changes, message", [
    ("GRAIL/MiniGrid-Optimal-v0", {}, {}, 'its task = "GRAIL/MiniGrid-Suboptimal-v1", not "GRAIL/MiniGrid-Optimal-v0"'),
    (TASK.id, {}, {}, "its params.turn_prob = 0.5, not 1.0"),
    (TASK.id, {"turn_prob": 0.5, "max_steps": 80}, {}, "its env.max_steps = 60, not 80"),
    (TASK.id, {"turn_prob": 0.5}, {"regime": "optimal"}, 'its regime = "optimal", not "suboptimal"'),
    (TASK.id, {"turn_prob": 0.5}, {"goals": [[7, 1], [7, 3]]}, "its goals = [[7, 1], [7, 3]], not [[7, 1], [7, 7]]"),
])
def test_a_dataset_exported_from_another_task_is_refused_naming_the_field(exported, tmp_path, task_id, params,
                                                                          changes, message):
    _, paths = exported
    path = with_metadata(copy_of(paths[0], tmp_path / "d"), **changes) if changes else paths[0]
    with pytest.raises(grail_bench.UserError) as info:
        grail_bench.make_task(task_id, demos=str(path), **params)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_dataset_recorded_elsewhere_is_checked_by_spaces_and_goal_labels(exported, tmp_path):
    _, paths = exported
    path = without_metadata(copy_of(paths[0], tmp_path / "d"))
    other = grail_bench.make_task("GRAIL/MiniGrid-Optimal-v0", demos=str(path))  # same goals and spaces
    assert (other.n_train, other.n_demos) == (7, 10) and other.generate_demos(0).keys() == set(other.goals)
    with pytest.raises(grail_bench.UserError, match="needs training and test episodes"):
        grail_bench.make_task("GRAIL/MiniGrid-Optimal-4Goals-v0", demos=str(path))
    with pytest.raises(grail_bench.UserError, match="observation space"):
        grail_bench.make_task("GRAIL/PandaReach-Optimal-v0", expert="scripted", demos=str(path))


@pytest.mark.parametrize("key, episode, value, message", [
    ("observations", 3, [99, 4, 0], "episode 3: observations lie outside the env's space MultiDiscrete([9 9 4])"),
    ("actions", 12, 7, "episode 12: actions lie outside the env's space Discrete(4)"),
])
def test_observations_or_actions_outside_the_spaces_are_refused_naming_the_episode(exported, tmp_path, key,
                                                                                   episode, value, message):
    _, paths = exported
    path = with_episode(copy_of(paths[0], tmp_path / "d"), episode, key, 2, value)
    with pytest.raises(grail_bench.UserError) as info:
        load_demos(TASK, str(path), 0)
    assert message in str(info.value) and str(info.value).endswith("at step 2") and "\n" not in str(info.value)


def test_episodes_without_goal_labels_are_refused(exported, tmp_path):
    import minari

    _, paths = exported
    path = copy_of(paths[0], tmp_path / "d")
    storage = minari.MinariDataset(path / "data").storage
    storage.update_episode_metadata([{"split": "train"}] * storage.total_episodes)  # goals gone
    with h5py.File(path / "data" / "main_data.hdf5", "a") as f:
        for i in range(storage.total_episodes):
            f[f"episode_{i}"].attrs.pop("goal", None)
    with pytest.raises(grail_bench.UserError, match="has no goal label"):
        load_demos(TASK, str(path), 0)


@pytest.fixture(scope="module")
def store(exported, tmp_path_factory):
    """A results store holding one run from the datasets."""
    out, _ = exported
    path = tmp_path_factory.mktemp("store") / "results.sqlite"
    with ResultsStore(path) as results:
        evaluate(TASK.id, [("bc", {"n_epochs": 1})], seeds=1, observability=[0.5], store=results,
                 task_params={"turn_prob": 0.5, "demos": str(out)})
    return path


def contents(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


def test_run_refuses_what_does_not_fit_in_one_line_and_leaves_the_store_alone(exported, store, tmp_path):
    out, paths = exported
    recorded = without_metadata(copy_of(paths[0], tmp_path / "recorded"))
    off_space = with_episode(copy_of(paths[0], tmp_path / "off"), 3, "observations", 0, [99, 4, 0])
    before = contents(store.parent)
    for args, message in (
        (["-t", "GRAIL/MiniGrid-Optimal-v0", "--demos", str(paths[0])], 'its task = "GRAIL/MiniGrid-Suboptimal-v1"'),
        (["-t", TASK.id, "--demos", str(paths[0])], "its params.turn_prob = 0.5, not 1.0"),
        (["-t", TASK.id, "--param", "turn_prob=0.5", "--demos", str(off_space)], "episode 3: observations lie outside"),
        (["-t", "GRAIL/PandaReach-Optimal-v0", "--demos", str(recorded)], "observation space"),
        (["-t", "GRAIL/MiniGrid-Optimal-4Goals-v0", "--demos", str(recorded)], "needs training and test episodes"),
        (["-t", TASK.id, "--demos", str(tmp_path / "nothing")], "no Minari dataset"),
        (["-t", TASK.id, "--param", "turn_prob=0.5", "--demos", str(out), "--seeds", "3"],
         "no dataset exported with seed 2 (seeds there: [0, 1])"),
        (["-t", "GRAIL/Nope-v0"], "unknown task 'GRAIL/Nope-v0'"),
        (["-t", TASK.id, "--param", "max_steps=-1"], "env.max_steps: expected a positive integer, got -1"),
    ):
        seeds = [] if "--seeds" in args else ["--seeds", "1"]
        result = cli("run", "-r", "bc", *seeds, "--no-progress", "--store", str(store), *args)
        one_error_line(result, message)
    assert contents(store.parent) == before


def test_export_into_a_relative_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = cli("export", "-t", TASK.id, "--param", "turn_prob=0.5", "--out", "datasets/")
    assert result.exit_code == 0, result.output
    path = tmp_path / "datasets" / dataset_id(TASK, 0)
    assert (path / "data" / "main_data.hdf5").is_file()
    assert load_demos(TASK, "datasets/", 0).n_train == 7  # relative sources read as well


def test_a_failed_export_leaves_nothing_behind(tmp_path, monkeypatch):
    real_write = export_module._write

    def write_one_then_fail(minari, task, seed, ident, spec, final):
        if seed == 1:
            raise OSError(28, "No space left on device", str(final))
        return real_write(minari, task, seed, ident, spec, final)

    monkeypatch.setattr(export_module, "_write", write_one_then_fail)
    out = tmp_path / "out"
    with pytest.raises(OSError):
        export(TASK, [0, 1], out)
    assert not out.exists()  # the seed 0 dataset, the namespace folder and the folder itself are gone
    out.mkdir()
    (out / "mine.txt").write_text("kept")
    result = cli("export", "-t", TASK.id, "--param", "turn_prob=0.5", "--seeds", "2", "--out", str(out))
    one_error_line(result, "No space left on device")
    assert [p.name for p in out.iterdir()] == ["mine.txt"]  # what was there before stays


def test_export_checks_its_output_before_any_work(tmp_path, monkeypatch):
    monkeypatch.setattr(export_module, "_write", lambda *a: pytest.fail("a dataset was written"))
    (tmp_path / "file").write_text("")
    with pytest.raises(grail_bench.UserError, match="cannot write the folder .*file: it is a file"):
        export(TASK, [0], tmp_path / "file")
    (tmp_path / "out" / dataset_id(TASK, 1)).mkdir(parents=True)
    with pytest.raises(grail_bench.UserError, match=r"seed1-v0 exists already"):
        export(TASK, [0, 1], tmp_path / "out")  # seed 0 is not written before seed 1 is found taken
    with pytest.raises(grail_bench.UserError, match="seeds"):
        export(TASK, [-1], tmp_path / "out")
    one_error_line(cli("export", "-t", TASK.id, "--out", str(tmp_path / "file")), "it is a file")
