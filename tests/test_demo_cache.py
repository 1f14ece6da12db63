"""Demonstrations kept on disk: identical to generated ones, generated once per key, regenerated when it changes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from grail_bench.core.trajectory import Trajectory

import grail_bench
from grail_bench.core.errors import UserError
from grail_bench.task import demo_cache

# The scripted expert keeps this cheap; the SAC expert's demonstrations go through the same code.
PANDA = {"expert": "scripted", "n_demos": 3, "n_train": 2}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path))
    return tmp_path / demo_cache.KIND


def generated(task, seed: int):
    """The demonstrations as the domain generates them, bypassing the cache."""
    from grail_bench.core.seeding import DEMOS, goal_rng

    return {g: task.spec.generate_demos(task, g, task.n_demos, goal_rng(seed, g, DEMOS)) for g in task.goals}


def assert_same(got, expected):
    assert list(got) == list(expected)
    for goal in expected:
        assert len(got[goal]) == len(expected[goal])
        for a, b in zip(got[goal], expected[goal]):
            assert a.obs.dtype == b.obs.dtype and a.acts.dtype == b.acts.dtype and a.terminal == b.terminal
            np.testing.assert_array_equal(a.obs, b.obs)
            np.testing.assert_array_equal(a.acts, b.acts)
            assert list(a.infos) == list(b.infos)


@pytest.mark.parametrize("task_id, params", [("GRAIL/PandaReach-Gaussian-0.1-v0", PANDA),
                                             ("GRAIL/PointMaze-Noisy-0.1-v0", {"n_demos": 2, "n_train": 1})])
def test_cached_demonstrations_are_the_generated_ones_and_generated_once(cache, monkeypatch, task_id, params):
    task = grail_bench.make_task(task_id, **params)
    expected = generated(task, seed=3)
    assert_same(task.generate_demos(seed=3), expected)  # generated and written
    assert len(list(cache.glob("*.npz"))) == len(task.goals)

    def fail(*_):
        raise AssertionError("a cached goal was generated again")

    monkeypatch.setattr(type(task.spec), "generate_demos", fail)
    assert_same(task.generate_demos(seed=3), expected)  # read back


def test_what_the_demonstrations_depend_on_keys_the_cache(cache):
    task = grail_bench.make_task("GRAIL/PandaReach-Gaussian-0.1-v0", **PANDA)
    base = task.generate_demos(seed=0)
    other_seed = task.generate_demos(seed=1)
    noisier = grail_bench.make_task("GRAIL/PandaReach-Gaussian-0.1-v0", sigma=0.3, **PANDA).generate_demos(seed=0)
    goal = task.goals[0]
    assert not np.array_equal(base[goal][0].acts, other_seed[goal][0].acts)
    assert not np.array_equal(base[goal][0].acts, noisier[goal][0].acts)
    assert len(list(cache.glob("*.npz"))) == 3 * len(task.goals)
    # A goal's demonstrations are the same in every task that has it, so tasks sharing goals share entries.
    fewer_goals = dataclasses.replace(task, goals=task.goals[:2])
    assert_same(fewer_goals.generate_demos(seed=0), {g: base[g] for g in task.goals[:2]})
    assert len(list(cache.glob("*.npz"))) == 3 * len(task.goals)


def test_a_domains_own_packages_key_its_entries(cache, monkeypatch):
    """A domain naming its simulator's distribution (``packages``) gets new entries when that version changes."""
    from grail_bench.core import provenance

    task = grail_bench.make_task("GRAIL/PandaReach-Gaussian-0.1-v0", **PANDA)
    task.generate_demos(seed=0)
    monkeypatch.setattr(type(task.spec), "packages", ("some-simulator",), raising=False)
    task.generate_demos(seed=0)
    assert len(list(cache.glob("*.npz"))) == 2 * len(task.goals)  # the same demonstrations under a new key
    real = provenance.package_versions
    monkeypatch.setattr(demo_cache, "package_versions",
                        lambda names: real(names).replace('"some-simulator": null', '"some-simulator": "2.0"'))
    task.generate_demos(seed=0)
    assert len(list(cache.glob("*.npz"))) == 3 * len(task.goals)


@pytest.mark.parametrize("edited, changes", [("grail_bench.domains.panda_reach.demos", True),
                                              ("grail_bench.core.experts", True), ("grail_bench.core.rl", False)])
def test_the_key_follows_the_demonstrators_code_not_the_recognizers_training(monkeypatch, edited, changes):
    """Editing a domain's demonstrator or the experts' actor regenerates its demonstrations; editing how DRACO
    trains (grail_bench.core.rl) does not."""
    from importlib.util import find_spec
    from pathlib import Path

    def digest() -> str:
        demo_cache.source_digest.cache_clear()
        return demo_cache.source_digest("grail_bench.domains.panda_reach")

    before, path, read = digest(), Path(find_spec(edited).origin), Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes", lambda self: read(self) + (b"\n# edited" if self == path else b""))
    assert (digest() != before) is changes
    monkeypatch.undo()
    demo_cache.source_digest.cache_clear()


def test_a_corrupt_entry_is_regenerated(cache):
    task = grail_bench.make_task("GRAIL/PandaReach-Optimal-v0", **PANDA)
    expected = task.generate_demos(seed=0)
    for entry in cache.glob("*.npz"):
        entry.write_bytes(b"not an npz")
    with pytest.warns(UserWarning, match="unusable"):
        assert_same(task.generate_demos(seed=0), expected)


def test_infos_that_could_not_come_back_are_refused():
    traj = Trajectory(obs=np.zeros((2, 1)), acts=np.zeros(1), infos=np.array([{"is_success": True, "x": 1}]),
                      terminal=True)
    with pytest.raises(UserError, match="other than is_success"):
        demo_cache.pack([traj], "toy")
