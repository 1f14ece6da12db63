"""Reinforcement learning on a goal env's true reward (DRACO, GC-DRACO, and training domain experts)."""

from __future__ import annotations

import sys
from typing import Any, Callable, Sequence, TypeVar

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecMonitor
from stable_baselines3.sac.policies import SACPolicy

from grail_bench.core.ppo_update import NumpyPPO

SAC_DEFAULTS = {"learning_starts": 500, "batch_size": 128}

Algorithm = TypeVar("Algorithm", bound=BaseAlgorithm)


def silenced(model: Algorithm) -> Algorithm:
    """``model`` with a logger writing nowhere.

    An SB3 model that ``learn``s without a logger of its own configures SB3's default one, which creates an
    ``SB3-<date>`` folder in ``$TMPDIR`` (unless ``SB3_LOGDIR`` is set) and leaves it there.
    """
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def make_sac(env: gym.Env, net_arch: Sequence[int], seed: int = 0) -> SAC:
    """SB3 SAC with a small MLP, as the suite trains it (silenced: it leaves no log folder)."""
    return silenced(SAC("MlpPolicy", env, policy_kwargs={"net_arch": list(net_arch)}, seed=seed, verbose=0,
                        device="cpu", **SAC_DEFAULTS))


def vec_env(env_fn: Callable[[], gym.Env], n_envs: int, seed: int = 0) -> VecEnv:
    """``n_envs`` copies of ``env_fn()``'s env for an SB3 learner, monitored (its episode returns can be read).

    An env that offers a vectorised twin (a ``vector_copies(n)`` method, as MiniGrid's does) is stepped as one
    array operation; any other, or one wrapped, one copy after another in SB3's ``DummyVecEnv``.
    """
    first = env_fn()
    twin = getattr(first, "vector_copies", None) if first is first.unwrapped else None
    venv = twin(n_envs) if twin is not None else DummyVecEnv([lambda: first] + [env_fn] * (n_envs - 1))
    venv = VecMonitor(venv)
    venv.seed(seed)
    return venv


def make_ppo(env_fn: Callable[[], gym.Env], net_arch: Sequence[int], seed: int = 0, n_envs: int = 8,
             **kwargs: Any) -> PPO:
    """SB3 PPO on ``n_envs`` copies of an env (:func:`vec_env`), its update run in numpy
    (:class:`~grail_bench.core.ppo_update.NumpyPPO`, discrete and continuous actions alike: the same rule at a
    fraction of torch's overhead) wherever it can be mirrored, by SB3 otherwise. ``kwargs`` go to ``PPO`` (e.g.
    ``learning_rate``). Silenced (:func:`silenced`): it leaves no log folder."""
    venv = vec_env(env_fn, n_envs, seed)
    return silenced(NumpyPPO("MlpPolicy", venv, policy_kwargs={"net_arch": list(net_arch)}, n_steps=128,
                             batch_size=64, seed=seed, verbose=0, device="cpu", gaussian=True, **kwargs))


def empty_policy(algorithm: str, observation_space: gym.Space, action_space: gym.Space,
                 net_arch: Sequence[int] | None = None) -> BasePolicy:
    """An untrained policy of the architecture ``make_sac``/``make_ppo`` train, to load cached weights into.

    Args:
        algorithm: ``"sac"`` or ``"ppo"``.
        net_arch: Hidden layers; ``None`` for SB3's default.
    """
    kwargs = {} if net_arch is None else {"net_arch": list(net_arch)}
    cls = {"sac": SACPolicy, "ppo": ActorCriticPolicy}[algorithm]
    return cls(observation_space, action_space, lambda _: 0.0, **kwargs)


#: Points of a training curve (curves are evidence to look at, not logs).
CURVE_POINTS = 50


class ReturnCurve(BaseCallback):
    """Records the mean episode return of the environment's own reward (SB3's ``ep_rew_mean``) as training goes.

    A point every ``steps / CURVE_POINTS`` environment steps, once episodes have ended.
    """

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.every = max(1, steps // CURVE_POINTS)
        self.values: list[float] = []
        self._next = self.every

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.every
            if self.model.ep_info_buffer:
                self.values.append(float(np.mean([info["r"] for info in self.model.ep_info_buffer])))
        return True


def learn(model: BaseAlgorithm, steps: int) -> tuple[dict[str, Any], list[float]]:
    """Train (with a progress bar on a terminal); the policy's ``state_dict`` and its return curve.

    The model is :func:`silenced` first, so no log folder appears in ``$TMPDIR``.
    """
    curve = ReturnCurve(steps)
    silenced(model).learn(steps, progress_bar=sys.stderr.isatty(), callback=curve)
    return model.policy.state_dict(), curve.values

