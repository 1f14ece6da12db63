"""Training leaves nothing in ``$TMPDIR``: SB3's default logger would create an ``SB3-<date>`` folder there (and
torch its compiler cache, which the suite's ``single_thread`` sends to the suite's cache)."""

from __future__ import annotations

import tempfile

import gymnasium as gym
import pytest
from stable_baselines3 import PPO

from grail_bench.core.rl import learn, make_ppo, make_sac
from grail_bench.core.torchutil import single_thread


@pytest.fixture
def tmpdir_watched(tmp_path, monkeypatch):
    """``$TMPDIR`` (and ``tempfile.gettempdir()``) pointed at an empty folder; SB3_LOGDIR unset."""
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    monkeypatch.setattr(tempfile, "tempdir", None)
    assert tempfile.gettempdir() == str(tmp_path)
    return tmp_path


def test_a_suite_made_ppo_learns_without_a_log_folder(tmpdir_watched):
    with single_thread():  # as the suite trains
        model = make_ppo(lambda: gym.make("CartPole-v1"), [8], seed=0, n_envs=2)
        model.learn(256)  # SB3's own learn, as a caller may run it: the suite's models come silenced
    assert list(tmpdir_watched.iterdir()) == []


def test_sac_and_any_model_trained_through_learn_leave_no_log_folder(tmpdir_watched):
    with single_thread():
        learn(make_sac(gym.make("Pendulum-v1"), [8], seed=0), 16)
        learn(PPO("MlpPolicy", "CartPole-v1", n_steps=64, batch_size=32, seed=0, device="cpu"), 64)
    assert list(tmpdir_watched.iterdir()) == []
