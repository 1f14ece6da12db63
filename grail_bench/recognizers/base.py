"""The recognizer protocol every method (built-in or plugin) satisfies."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Mapping, Protocol, Sequence, runtime_checkable

if TYPE_CHECKING:
    import gymnasium as gym
    from imitation.data.types import Trajectory

Goal = tuple[float, ...]
EnvFactory = Callable[[Goal], "gym.Env"]


class RecognizerError(RuntimeError):
    """A recognizer broke the protocol (e.g. returned scores for the wrong goals)."""


@runtime_checkable
class Recognizer(Protocol):
    """A goal recognizer. No base class is needed: any object with these members works.

    Attributes:
        name: Short name, as registered (e.g. ``"bc"``).

    A recognizer that reloads cached models may also set ``fit_seconds`` in
    ``fit``: the training time its models cost, which the harness then reports
    instead of the (much shorter) loading time.
    """

    name: str

    def fit(self, demos: Mapping[Goal, Sequence[Trajectory]], env_factory: EnvFactory, *, seed: int) -> None:
        """Prepare to recognise the goals of ``demos``.

        Args:
            demos: The training demonstrations of every candidate goal.
            env_factory: ``env_factory(goal)`` builds the domain env pursuing
                ``goal`` (for methods that learn from interaction). The
                harness's factory also has a ``cache_key`` string naming the
                domain env, for reusing models across regimes.
            seed: Seed for everything random in fitting.
        """
        ...

    def score(self, observed: Trajectory) -> dict[Goal, float]:
        """Score every goal given to :meth:`fit`; higher means more likely.

        Args:
            observed: ``k`` observed actions and the ``k + 1`` states around
                them; ``observed.acts[t]`` was taken in ``observed.obs[t]``.
                It never carries the true goal.
        """
        ...


def recognizer_config(recognizer: Any) -> dict[str, Any]:
    """The recognizer's hyperparameters (``config`` attribute), or ``{}``."""
    config = getattr(recognizer, "config", None)
    return dict(config) if isinstance(config, Mapping) else {}


def observed_arrays(observed: Any, observation_space: Any, action_space: Any) -> tuple[Any, Any]:
    """Validate an observed trajectory and return its ``(states, actions)`` pairs.

    Args:
        observed: An ``imitation`` ``Trajectory`` (or anything with ``obs`` and ``acts``).
        observation_space: The space each state must belong to.
        action_space: The space each action must belong to.

    Returns:
        ``(obs[:k], acts)``: the ``k`` states in which the ``k`` actions were taken.

    Raises:
        ValueError: For an empty prefix, mismatched lengths or wrong shapes.
    """
    import numpy as np

    try:
        obs, acts = np.asarray(observed.obs), np.asarray(observed.acts)
    except AttributeError:
        raise ValueError(f"expected a Trajectory with obs and acts, got {type(observed).__name__}") from None
    if len(acts) == 0:
        raise ValueError("the observed trajectory is empty: at least one action is needed")
    if len(obs) != len(acts) + 1:
        raise ValueError(f"malformed trajectory: {len(obs)} states for {len(acts)} actions (need actions + 1)")
    if obs.shape[1:] != observation_space.shape:
        raise ValueError(f"observed states have shape {obs.shape[1:]}, the env's are {observation_space.shape}")
    if acts.shape[1:] != action_space.shape:
        raise ValueError(f"observed actions have shape {acts.shape[1:]}, the env's are {action_space.shape}")
    return obs[: len(acts)], acts
