"""The suite's own Trajectory: imitation's fields and checks, and any object with those fields is accepted."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import grail_bench
from grail_bench.core.trajectory import Trajectory, flatten, until_success
from grail_bench.recognizers import make_recognizer
from grail_bench.task.observation import observe


def test_a_trajectory_has_one_observation_more_than_actions_and_at_least_one_action():
    with pytest.raises(ValueError, match="at least one action"):
        Trajectory(obs=np.zeros((1, 3)), acts=np.zeros(0))
    with pytest.raises(ValueError, match="one observation more than actions, got 3 observations and 3 actions"):
        Trajectory(obs=np.zeros((3, 3)), acts=np.zeros(3))
    with pytest.raises(ValueError, match="one info per action, got 1 infos and 2 actions"):
        Trajectory(obs=np.zeros((3, 3)), acts=np.zeros(2), infos=np.array([{}]))


def test_equal_by_content_and_cut_after_the_goal():
    infos = np.array([{"is_success": False}, {"is_success": True}, {"is_success": True}])
    traj = Trajectory(obs=np.arange(8).reshape(4, 2), acts=np.array([0, 1, 3]), infos=infos)
    assert traj == Trajectory(obs=np.arange(8).reshape(4, 2), acts=np.array([0, 1, 3]), infos=infos.copy())
    assert traj != Trajectory(obs=np.arange(8).reshape(4, 2), acts=np.array([0, 1, 2]), infos=infos)
    cut = until_success(traj)
    assert len(cut) == 2 and cut.obs.tolist() == [[0, 1], [2, 3], [4, 5]]
    obs, acts = flatten([traj, cut])
    assert obs.shape == (5, 2) and acts.tolist() == [0, 1, 3, 0, 1]


def test_an_object_with_a_trajectorys_fields_scores_as_one():
    task = grail_bench.make_task("GRAIL/MiniGrid-Biased-v0")
    train, test = task.split(task.generate_demos(seed=0))
    rec = make_recognizer("bc", n_epochs=2)
    rec.fit(train, task.env_factory(), seed=0)
    observed = observe(test[task.goals[0]][0], 0.5)
    # imitation's Trajectory, or a researcher's own type, with the same fields
    theirs = SimpleNamespace(obs=observed.obs, acts=observed.acts, infos=None, terminal=False)
    assert rec.score(theirs) == rec.score(observed)
