"""The recognizer protocol every method (built-in or plugin) satisfies."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping, Protocol, Sequence, runtime_checkable

from grail_bench.errors import UserError
from grail_bench.trajectory import EnvFactory, Goal

if TYPE_CHECKING:
    from imitation.data.types import Trajectory


class RecognizerError(UserError):
    """A recognizer broke the protocol (e.g. returned scores for the wrong goals)."""


@dataclass(frozen=True)
class FitReport:
    """What a fit cost.

    Attributes:
        train_seconds: Training time of the fitted models, including that of
            models reloaded from a cache (what they cost when trained), so
            cache hits do not report near-zero training.
        trained: Models trained in this fit.
        reused: Models reloaded from the cache.
    """

    train_seconds: float
    trained: int = 0
    reused: int = 0


@runtime_checkable
class Recognizer(Protocol):
    """A goal recognizer. No base class is needed: any object with these members works.

    Attributes:
        name: Short name, as registered (e.g. ``"bc"``).
        config: Hyperparameters (JSON-able); they key stored results and cached models.
        default_scorer: What :meth:`score` uses when no scorer is named: a
            registered scorer (:mod:`grail_bench.scoring`), or any label for
            a recognizer with its own scoring.

    A registered class may also carry ``paper_name``, the method's name in
    publications (e.g. ``"BC-GRAIL"``), which the leaderboard shows, and
    ``score_prefixes(observed, scorer=None) -> {goal: (T,) array}``, the
    scores of every prefix ``k = 1..T`` at once, which online mode then uses
    instead of calling :meth:`score` once per prefix.
    """

    name: str
    config: Mapping[str, Any]
    default_scorer: str

    def exposes(self, action_space: Any) -> frozenset[str]:
        """The :class:`~grail_bench.scoring.PolicyOutput` fields this recognizer
        can give registered scorers on ``action_space``; empty if it scores only
        with :attr:`default_scorer`."""
        ...

    def fit(self, demos: Mapping[Goal, Sequence[Trajectory]], env_factory: EnvFactory, *, seed: int,
            cache_key: str | None = None) -> FitReport | None:
        """Prepare to recognise the goals of ``demos``.

        Args:
            demos: The training demonstrations of every candidate goal.
            env_factory: ``env_factory(goal)`` builds the domain env pursuing
                ``goal`` (for methods that learn from interaction).
            seed: Seed for everything random in fitting.
            cache_key: Names the domain env (not the regime); with it a
                recognizer may cache trained models and reuse them across
                fits and regimes. ``None``: do not cache.

        Returns:
            What fitting cost; ``None`` lets the harness time the call.
        """
        ...

    def score(self, observed: Trajectory, scorer: str | None = None) -> dict[Goal, float]:
        """Score every goal given to :meth:`fit`; higher means more likely.

        Args:
            observed: ``k`` observed actions and the ``k + 1`` states around
                them; ``observed.acts[t]`` was taken in ``observed.obs[t]``.
                It never carries the true goal.
            scorer: A registered scorer among those :meth:`exposes` allows;
                ``None`` for :attr:`default_scorer`.
        """
        ...


def observed_arrays(observed: Any, observation_space: Any, action_space: Any) -> tuple[Any, Any]:
    """Validate an observed trajectory and return its ``(states, actions)`` pairs.

    Args:
        observed: An ``imitation`` ``Trajectory`` (or anything with ``obs`` and ``acts``).
        observation_space: The space each state must belong to.
        action_space: The space each action must belong to.

    Returns:
        ``(obs[:k], acts)``: the ``k`` states in which the ``k`` actions were taken.

    Raises:
        UserError: For an empty prefix, mismatched lengths or wrong shapes.
    """
    import numpy as np

    try:
        obs, acts = np.asarray(observed.obs), np.asarray(observed.acts)
    except AttributeError:
        raise UserError(f"expected a Trajectory with obs and acts, got {type(observed).__name__}") from None
    if len(acts) == 0:
        raise UserError("the observed trajectory is empty: at least one action is needed")
    if len(obs) != len(acts) + 1:
        raise UserError(f"malformed trajectory: {len(obs)} states for {len(acts)} actions (need actions + 1)")
    if obs.shape[1:] != observation_space.shape:
        raise UserError(f"observed states have shape {obs.shape[1:]}, the env's are {observation_space.shape}")
    if acts.shape[1:] != action_space.shape:
        raise UserError(f"observed actions have shape {acts.shape[1:]}, the env's are {action_space.shape}")
    return obs[: len(acts)], acts
