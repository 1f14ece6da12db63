"""GAIL-GRAIL and AIRL-GRAIL: adversarial imitation, one PPO generator per goal.

Both train after imitation 1.0.1's algorithms (:mod:`grail_bench.core.adversarial`:
the same seed trains the same weights) with an SB3 PPO generator (``MlpPolicy``)
and the paper's hyperparameters: PPO batch 32, gamma 0.95, learning rate 3e-4; 8
discriminator updates per round, generator replay buffer 512, demo batch 16.
Rollouts run in the goal's own env with a fixed horizon (no early
termination; 8 copies, vectorised where the domain offers it); the
demonstrations are used whole, absorbed tail included, as the trainers require
equal-length episodes. Scoring uses the trained generator policy, exactly as
BC-GRAIL uses its cloned policy. Two things make a fit ~3.4x faster than
imitation 1.0.1's loop on SB3's PPO while training the same model: PPO's update
in numpy (:mod:`grail_bench.core.ppo_update`, equal to SB3's to float32
rounding) and a rollout's learned rewards computed in one call at its end
(bit for bit the same weights).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Annotated, Any, Callable, Literal, Sequence

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.policies import ActorCriticPolicy

from grail_bench.core.adversarial import (
    AIRL,
    GAIL,
    BasicRewardNet,
    BasicShapedRewardNet,
    RunningNorm,
    VariableHorizonError,
)
from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.ppo_update import GAEBuffer, NumpyPPO
from grail_bench.core.rl import empty_policy, vec_env
from grail_bench.core.torchutil import unchecked_distributions
from grail_bench.core.trajectory import EnvFactory, Goal, Trajectory
from grail_bench.recognizers.policy import PolicyRecognizer, spaces_of
from grail_bench.recognizers.evidence import OffSupport, off_support_setting
from grail_bench.recognizers.scored import ActionBox, action_box_setting
from grail_bench.stats.metrics import thin

# Adam's fused kernel: the same update rule as the default per-tensor loop in one kernel per step
# (the loop was a fifth of each torch PPO update on these small networks).
_ADAM = {"fused": True}
# The generator's Adam: SB3's PPO default eps (1e-5; SB3 sets it only when given no optimizer arguments).
_GENERATOR_ADAM = {"eps": 1e-5}
#: PPO's update: in numpy (the same rule, ~4x faster on these networks) or SB3's torch ``train()``.
UPDATES: dict[str, type[PPO]] = {"numpy": NumpyPPO, "torch": PPO}


class _RolloutRewards:
    """The learned rewards of a whole rollout from one batched call, not one call per environment step.

    The trainer's reward wrapper asks the discriminator for the reward of every step as it is taken (a torch
    forward pass per step, a fifth of a fit). PPO reads those rewards only when it computes advantages at the
    end of the rollout, and the discriminator does not change during a rollout. So the wrapper is given zeros
    and the transitions are kept; the rollout buffer adds their rewards, computed at once, before it computes
    advantages. SB3 adds its truncation bootstrap to the same entries, and float addition commutes, so the
    buffer holds the same sums (a test checks the trained weights).
    """

    def __init__(self, reward_fn: Callable[..., np.ndarray]) -> None:
        self.reward_fn = reward_fn
        self.steps: list[tuple[np.ndarray, ...]] = []

    def __call__(self, obs: np.ndarray, acts: np.ndarray, next_obs: np.ndarray, dones: np.ndarray) -> np.ndarray:
        self.steps.append((obs, acts, next_obs, dones))
        return np.zeros(len(dones), dtype=np.float32)

    def collect(self) -> np.ndarray:
        """The kept steps' rewards, ``(n_steps, n_envs)``; forgets them."""
        obs, acts, next_obs, dones = (np.stack(arrays) for arrays in zip(*self.steps))
        self.steps.clear()
        n_steps, n_envs = dones.shape
        flat = [a.reshape(n_steps * n_envs, *a.shape[2:]) for a in (obs, acts, next_obs, dones)]
        return np.asarray(self.reward_fn(*flat), dtype=np.float32).reshape(n_steps, n_envs)


class _RewardedRolloutBuffer(GAEBuffer):
    """The rollout buffer (SB3 2.2's GAE on every SB3) that adds a rollout's learned rewards
    (:class:`_RolloutRewards`) before advantages."""

    rollout_rewards: _RolloutRewards | None = None

    def compute_returns_and_advantage(self, last_values: torch.Tensor, dones: np.ndarray) -> None:
        if self.rollout_rewards is not None:
            self.rewards += self.rollout_rewards.collect()
        super().compute_returns_and_advantage(last_values, dones)


@dataclass(frozen=True)
class AdversarialConfig:
    """The settings GAIL- and AIRL-GRAIL share (the paper's hyperparameters where it states them).

    Attributes:
        total_timesteps: Generator environment steps per goal; each method's default is
            its budget study's plateau (docs/guides/budgets.md).
        n_envs: Parallel copies of the goal env feeding PPO.
        n_steps: PPO rollout length per env and round (``n_envs * n_steps``
            generator steps per round).
        batch_size: PPO minibatch (paper: 32).
        gamma: PPO discount (paper: 0.95).
        learning_rate: PPO learning rate (paper: 3e-4).
        n_epochs: PPO epochs per round (SB3's default).
        n_disc_updates_per_round: Paper: 8.
        gen_replay_buffer_capacity: Paper: 512.
        demo_batch_size: Paper: 16.
        update: How PPO's update runs: ``"numpy"`` (the same update written out in numpy,
            :mod:`grail_bench.core.ppo_update`; ~4x faster on these networks, equal to SB3's to
            float32 rounding) or ``"torch"`` (SB3's own ``train()``), on discrete and continuous actions
            alike (continuous ones were left to SB3's ``train()`` before; their generators are keyed apart).
        off_support: What a goal's generator outputs at states off its goal's support when scored:
            ``"trust"`` (its own output: the paper's method), ``"stay"`` (the domain's no-op) or ``"uniform"``
            (no preference); see :class:`~grail_bench.recognizers.evidence.Evidence`. Scoring only: the trained
            policies are shared across its values.
        action_box: ``"ignore"`` (the mean as it is: the published method) or ``"clip"`` (the mean clipped to the
            env's action box, as SB3's deterministic ``predict`` returns it); continuous actions only, scoring
            only (:func:`~grail_bench.recognizers.scored.action_box_setting`).
    """

    # budget-gail: 20 000 steps is on the plateau of both 6-goal MiniGrid tasks (5 seeds, 30 % observed)
    total_timesteps: Annotated[int, Range(1, 100_000_000)] = 20_000
    n_envs: Annotated[int, Range(1, 256)] = 8
    n_steps: Annotated[int, Range(1, 100_000)] = 64
    batch_size: Annotated[int, Range(1, 1_000_000)] = 32
    gamma: float = 0.95
    learning_rate: float = 3e-4
    n_epochs: Annotated[int, Range(1, 10_000)] = 10
    n_disc_updates_per_round: Annotated[int, Range(1, 10_000)] = 8
    gen_replay_buffer_capacity: Annotated[int, Range(1, 10_000_000)] = 512
    demo_batch_size: Annotated[int, Range(1, 1_000_000)] = 16
    update: Literal["numpy", "torch"] = "numpy"
    off_support: OffSupport = off_support_setting()
    action_box: ActionBox = action_box_setting()

    def __post_init__(self) -> None:
        sizes = (self.total_timesteps, self.n_envs, self.n_steps, self.batch_size, self.n_epochs,
                 self.demo_batch_size, self.n_disc_updates_per_round, self.gen_replay_buffer_capacity)
        if min(sizes) < 1:
            raise UserError("sizes and step counts must be positive")
        # SB3's PPO asserts both (advantages are normalised per minibatch and per rollout).
        if self.batch_size < 2:
            raise UserError(f"batch_size must be at least 2 (PPO normalises advantages per minibatch), got "
                            f"{self.batch_size}")
        if self.n_steps * self.n_envs < 2:
            raise UserError(f"n_steps * n_envs must be at least 2 (the steps of one PPO rollout), got "
                            f"{self.n_steps} * {self.n_envs}")
        if not 0 < self.gamma <= 1 or not self.learning_rate > 0:
            raise UserError(f"gamma must be in (0, 1] and learning_rate > 0, got {self.gamma} and {self.learning_rate}")
        if self.update not in UPDATES:
            raise UserError(f"update must be one of {', '.join(UPDATES)}, got {self.update!r}")


@dataclass(frozen=True)
class AIRLConfig(AdversarialConfig):
    """AIRL-GRAIL's settings: :class:`AdversarialConfig`'s, with its own budget and the reward's shaping.

    Attributes:
        total_timesteps: 40 000, the plateau of its own study (``budget-airl``: 20 000 falls short on the
            optimal 6-goal task).
        shaping_discount: The discount of the reward's potential shaping. AIRL's shaping
            ``g(s, a) + discount * h(s') - h(s)`` leaves the optimal policy unchanged only when its
            discount is the generator's (Fu et al. 2018; Ng et al. 1999), so it defaults to ``gamma``
            (imitation 1.0.1's default, 0.99, would differ from the paper's 0.95).
    """

    total_timesteps: Annotated[int, Range(1, 100_000_000)] = 40_000
    shaping_discount: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        discount = self.gamma if self.shaping_discount is None else self.shaping_discount
        if not 0 < discount <= 1:
            raise UserError(f"shaping_discount must be in (0, 1], got {discount}")
        object.__setattr__(self, "shaping_discount", float(discount))


class AdversarialRecognizer(PolicyRecognizer):
    """Shared training loop of GAIL- and AIRL-GRAIL (settings: :class:`AdversarialConfig`).

    Its ``scorer`` defaults to ``"mse"``.
    """

    trainer_cls: type = GAIL
    reward_net_cls: type = BasicRewardNet
    Config = AdversarialConfig
    config: AdversarialConfig

    def _generator(self, goal: Goal, env_factory: EnvFactory, n_envs: int, seed: int = 0) -> PPO:
        cfg = self.config
        # Monitored, so the generator's returns under the environment's own reward can be read (a curve).
        venv = vec_env(lambda: env_factory(goal), n_envs, seed)
        optimizer = {**_GENERATOR_ADAM, **(_ADAM if cfg.update == "torch" else {})}  # numpy's update skips it
        numpy = {"gaussian": True} if cfg.update == "numpy" else {}  # continuous actions too
        return UPDATES[cfg.update](
            "MlpPolicy", venv, batch_size=cfg.batch_size, gamma=cfg.gamma, learning_rate=cfg.learning_rate,
            n_steps=cfg.n_steps, n_epochs=cfg.n_epochs, seed=seed, verbose=0, device="cpu",
            policy_kwargs={"optimizer_kwargs": optimizer}, rollout_buffer_class=_RewardedRolloutBuffer, **numpy)

    def model_key(self, goal: Goal) -> dict[str, Any]:
        """The numpy update runs continuous actions too (it once left them to SB3's), which keys those generators
        apart from ones SB3's update trained; discrete ones keep their keys."""
        if self.config.update == "numpy" and isinstance(self.action_space, spaces.Box):
            return {"update": "numpy"}
        return {}

    def new_policy(self, goal: Goal, env_factory: EnvFactory) -> ActorCriticPolicy:
        return empty_policy("ppo", *spaces_of(env_factory, goal))

    def check_task(self, task: Any) -> None:
        """Refuse, where the run is planned, a task whose episodes may end before its horizon (its domain's
        ``ends_early``), besides :meth:`ScoredRecognizer.check_task`'s refusals.

        Raises:
            UserError: In one line saying why.
        """
        super().check_task(task)
        ends_early = getattr(task.spec, "ends_early", None)
        why = ends_early(task.env_params) if callable(ends_early) else None
        if why:
            raise UserError(self._variable_horizon(f"{task.id}: {why}"))

    def _variable_horizon(self, what: str) -> str:
        return (f"recognizer {self.name!r}: {what}, but GAIL and AIRL train on episodes of one fixed length (an "
                "episode that ends early tells the discriminator whose it is)")

    def train_policy(self, goal: Goal, demos: Sequence[Trajectory], env_factory: EnvFactory,
                     seed: int) -> tuple[ActorCriticPolicy, dict[str, list[float]]]:
        cfg = self.config
        generator = self._generator(goal, env_factory, cfg.n_envs, seed)
        venv = generator.get_env()
        reward_net = self.reward_net_cls(venv.observation_space, venv.action_space,
                                         normalize_input_layer=RunningNorm, **self.reward_net_kwargs())
        demo_batch = min(cfg.demo_batch_size, sum(len(t.acts) for t in demos))
        with unchecked_distributions(), warnings.catch_warnings():
            warnings.filterwarnings("ignore", category=UserWarning, module="stable_baselines3")
            trainer = self.trainer_cls(
                demonstrations=list(demos), demo_batch_size=demo_batch, venv=venv, gen_algo=generator,
                reward_net=reward_net, n_disc_updates_per_round=cfg.n_disc_updates_per_round,
                gen_replay_buffer_capacity=cfg.gen_replay_buffer_capacity, allow_variable_horizon=False,
                disc_opt_kwargs=_ADAM,
            )
            rewards = _RolloutRewards(trainer.venv_wrapped.reward_fn)
            trainer.venv_wrapped.reward_fn = rewards
            generator.rollout_buffer.rollout_rewards = rewards
            # The rounds of imitation 1.0.1's train(): a generator round, then the discriminator's updates.
            rounds = max(1, cfg.total_timesteps // trainer.gen_train_timesteps)
            disc_acc, gen_return = [], []
            for _ in range(rounds):
                try:
                    trainer.train_gen(trainer.gen_train_timesteps)
                except VariableHorizonError as exc:  # a domain that does not declare ends_early
                    raise UserError(self._variable_horizon(f"goal {list(goal)}'s generator {exc}")) from None
                stats = None
                for _ in range(cfg.n_disc_updates_per_round):
                    stats = trainer.train_disc()
                if stats is not None:
                    disc_acc.append(float(stats["disc_acc"]))
                if generator.ep_info_buffer:
                    gen_return.append(float(np.mean([info["r"] for info in generator.ep_info_buffer])))
        venv.close()
        return generator.policy, {"disc_acc": thin(disc_acc), "gen_return": thin(gen_return)}


    def reward_net_kwargs(self) -> dict[str, Any]:
        """Extra keyword arguments of the reward network."""
        return {}


class GAILRecognizer(AdversarialRecognizer):
    """GAIL-GRAIL (GAIL after imitation 1.0.1's algorithm, a ``BasicRewardNet`` discriminator; settings:
    :class:`AdversarialConfig`)."""

    name = "gail"
    paper_name = "GAIL-GRAIL"
    trainer_cls = GAIL
    reward_net_cls = BasicRewardNet


class AIRLRecognizer(AdversarialRecognizer):
    """AIRL-GRAIL (AIRL after imitation 1.0.1's algorithm, a ``BasicShapedRewardNet`` with a state potential;
    settings: :class:`AIRLConfig`)."""

    name = "airl"
    paper_name = "AIRL-GRAIL"
    trainer_cls = AIRL
    reward_net_cls = BasicShapedRewardNet
    Config = AIRLConfig
    config: AIRLConfig

    def reward_net_kwargs(self) -> dict[str, Any]:
        return {"discount_factor": self.config.shaping_discount}
