"""What the domains share beyond the task's :class:`~grail_bench.task.domain.Domain` protocol.

:class:`GoalModel` is one goal's demonstrator with a known likelihood, as a
domain's ``demonstrator(task, goal)`` builds it for the regimes it lists in
``ceiling_regimes``; the harness's Bayes ceiling
(:mod:`grail_bench.harness.ceiling`) reads nothing else of a domain.
"""

from __future__ import annotations

from typing import Any, Hashable, Iterator, Protocol, Sequence

import numpy as np

from grail_bench.task.domain import Domain
from grail_bench.task.observation import Selection

__all__ = ["Domain", "GoalModel"]


class GoalModel(Protocol):
    """One goal's demonstrator with a known likelihood, as a domain's ``demonstrator(task, goal)`` builds it.

    A demonstration is any hashable the model understands (an action
    sequence, a route); an observation is a tuple of hashable pairs.

    Attributes:
        enumerable: Whether :meth:`support` lists every demonstration (else only
            Monte Carlo estimates are possible).
        action_size: How many trailing entries of a pair are the action (the rest is the state).
    """

    enumerable: bool
    action_size: int

    def support(self) -> Iterator[tuple[Any, float]]:
        """Every demonstration with its probability (only when :attr:`enumerable`)."""
        ...

    def span(self, demonstration: Any, selection: Selection) -> Sequence[Hashable]:
        """The pairs a protocol samples from in one demonstration."""
        ...

    def observations(self, demonstration: Any, selection: Selection) -> Iterator[tuple[tuple, float]]:
        """Every observation of one demonstration with its probability under the protocol."""
        ...

    def sample_observation(self, rng: np.random.Generator, selection: Selection) -> tuple:
        """A demonstration and then its observation, drawn as the harness draws them."""
        ...

    def likelihood(self, observation: tuple, selection: Selection) -> float:
        """Probability that this goal's demonstrator yields ``observation`` under the protocol."""
        ...
