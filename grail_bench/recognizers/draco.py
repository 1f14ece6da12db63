"""DRACO (Nageris et al. 2024): one RL policy per goal on the true reward, Wasserstein scoring."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any, Literal, Sequence

from gymnasium import spaces
from grail_bench.core.trajectory import Trajectory
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.policies import BasePolicy

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.rl import empty_policy, learn, make_ppo, make_sac
from grail_bench.core.trajectory import EnvFactory, Goal
from grail_bench.recognizers.policy import PolicyRecognizer, spaces_of
from grail_bench.recognizers.evidence import OffSupport, off_support_setting
from grail_bench.recognizers.scored import ActionBox, action_box_setting
from grail_bench.stats.metrics import thin

ALGORITHMS = ("ppo", "sac")
# Default steps per goal of each algorithm. PPO: budget-draco-ppo's plateau (PandaReach-Aligned-Gaussian-0.3,
# 2 % observed, 5 seeds: 5000 / 15 000 / 50 000 / 150 000 steps give F1 0.55 / 0.78 / 0.88 / 0.91; only 150 000
# reaches its own interval; the curve may still rise beyond it). SAC: budget-draco-sac's plateau (same task:
# 1500 / 5000 / 15 000 / 45 000 steps give F1 0.21 / 0.57 / 0.90 / 0.80; 15 000 is the best).
STEPS = {"ppo": 150_000, "sac": 15_000}


@dataclass(frozen=True)
class DRACOConfig:
    """DRACO's settings.

    Attributes:
        algorithm: ``"ppo"`` (the paper's: "trains each goal-directed policy via PPO", on discrete and
            continuous actions alike) or ``"sac"`` (continuous actions only; kept as a named configuration,
            ``--set draco.algorithm=sac``).
        sac_steps: SAC steps per goal (default 15 000, its budget study's plateau).
        ppo_steps: PPO steps per goal, over 8 env copies (default 150 000, its budget study's plateau).
            The chosen algorithm's budget is filled in; setting the other algorithm's is an error (it would
            train the chosen one at its full default budget), and it stays None, out of the configuration's
            key, so a change to the other algorithm's default leaves results and models valid.
        net_arch: Hidden layers of the policy.
        off_support: What a goal's policy outputs at states off its goal's support when scored: ``"trust"``
            (its own output: the published method), ``"stay"`` (the domain's no-op) or ``"uniform"`` (no
            preference); see :class:`~grail_bench.recognizers.evidence.Evidence`. DRACO learns from interaction
            alone, so its policies have no demonstrations of their own: a goal's support is still the states its
            *training demonstrations* visit (``fit`` receives them). Scoring only: the trained policies are shared
            across its values.
        action_box: ``"ignore"`` (the mean as it is: the published method) or ``"clip"`` (the mean clipped to the
            env's action box, as SB3's deterministic ``predict`` returns it); continuous actions only, scoring
            only (:func:`~grail_bench.recognizers.scored.action_box_setting`).
    """

    algorithm: Literal["ppo", "sac"] = "ppo"
    sac_steps: Annotated[int, Range(1, 100_000_000)] | None = field(default=None, metadata={"omit_none": True})
    ppo_steps: Annotated[int, Range(1, 100_000_000)] | None = field(default=None, metadata={"omit_none": True})
    net_arch: Annotated[tuple[int, ...], Range(1, 4096)] = (64, 64)
    off_support: OffSupport = off_support_setting()
    action_box: ActionBox = action_box_setting()

    def __post_init__(self) -> None:
        if self.algorithm not in ALGORITHMS:
            raise UserError(f"algorithm must be one of {', '.join(ALGORITHMS)}, got {self.algorithm!r}")
        given = {"ppo": self.ppo_steps, "sac": self.sac_steps}
        for other, budget in given.items():
            # A configuration stored by an older version repeats the other algorithm's default: accepted.
            if other != self.algorithm and budget is not None and budget != STEPS[other]:
                raise UserError(f"{other}_steps applies to algorithm={other}; with algorithm={self.algorithm} "
                                f"set {self.algorithm}_steps")
            if other != self.algorithm:
                object.__setattr__(self, f"{other}_steps", None)
        steps = STEPS[self.algorithm] if given[self.algorithm] is None else given[self.algorithm]
        if steps < 1 or not self.net_arch or min(self.net_arch) < 1:
            raise UserError("step budgets and hidden layer sizes must be positive")
        object.__setattr__(self, f"{self.algorithm}_steps", steps)
        object.__setattr__(self, "net_arch", tuple(self.net_arch))

    @property
    def steps(self) -> int:
        """The chosen algorithm's budget."""
        return self.ppo_steps if self.algorithm == "ppo" else self.sac_steps


class DRACORecognizer(PolicyRecognizer):
    """DRACO: PPO (as the paper trains it) or SAC per goal, on the env's own reward (settings:
    :class:`DRACOConfig`).

    It learns from interaction only (the demonstrations do not train it), so its
    cached policies are reused by every regime of the domain. Its ``scorer`` defaults to
    ``"wasserstein"`` (DRACO's). The demonstrations ``fit`` receives still say where each goal has
    evidence: its ``off_support`` rule and the ``occupancy`` scorer read each goal's training
    demonstrations, as for the imitation methods.
    """

    name = "draco"
    paper_name = "DRACO"
    default_scorer = "wasserstein"
    uses_demos = False
    Config = DRACOConfig
    config: DRACOConfig

    def exposes(self, action_space: spaces.Space) -> frozenset[str]:
        """The policy outputs on ``action_space``; SAC on discrete actions is refused here, where a run is planned,
        rather than when its fit starts."""
        self._algorithm(action_space)
        return super().exposes(action_space)

    def _algorithm(self, action_space: spaces.Space) -> str:
        if self.config.algorithm == "sac" and not isinstance(action_space, spaces.Box):
            raise UserError("draco: SAC needs continuous actions; use algorithm=ppo on this domain")
        return self.config.algorithm

    def model_key(self, goal: Goal) -> dict[str, Any]:
        """PPO runs its update in numpy (:func:`~grail_bench.core.rl.make_ppo`), which keys its models apart from
        ones SB3's update trained; SAC's keys are unchanged."""
        return {"update": "numpy"} if self.config.algorithm == "ppo" else {}

    def _model(self, goal: Goal, env_factory: EnvFactory, seed: int) -> BaseAlgorithm:
        env = env_factory(goal)
        if self._algorithm(env.action_space) == "sac":
            return make_sac(env, list(self.config.net_arch), seed)
        env.close()
        return make_ppo(lambda: env_factory(goal), list(self.config.net_arch), seed)

    def new_policy(self, goal: Goal, env_factory: EnvFactory) -> BasePolicy:
        observation_space, action_space = spaces_of(env_factory, goal)
        return empty_policy(self._algorithm(action_space), observation_space, action_space, list(self.config.net_arch))

    def train_policy(self, goal: Goal, demos: Sequence[Trajectory], env_factory: EnvFactory,
                     seed: int) -> tuple[BasePolicy, dict[str, list[float]]]:
        model = self._model(goal, env_factory, seed)
        _, returns = learn(model, self.config.steps)
        model.get_env().close()
        return model.policy, {"return": thin(returns)}
