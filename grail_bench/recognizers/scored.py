"""Recognizers whose score is a pluggable scorer over their goal policies' outputs."""

from __future__ import annotations

import abc
from typing import Any

import numpy as np

from grail_bench.scoring import PolicyOutput, Scorer, get_scorer
from grail_bench.recognizers.base import Goal


class ScoredRecognizer(abc.ABC):
    """Base of recognizers that expose :class:`~grail_bench.scoring.PolicyOutput`.

    Subclasses say what they expose for an action space and compute the
    outputs on an observation; scoring is then any registered scorer that can
    work from those outputs (``score`` uses :attr:`scorer`, ``score_with`` any).

    Args:
        scorer: Scorer used by :meth:`score`; defaults to :attr:`default_scorer`.
    """

    name: str = ""
    default_scorer: str = "mse"

    def __init__(self, scorer: str | None = None) -> None:
        self.scorer = scorer or self.default_scorer
        get_scorer(self.scorer)  # unknown names fail at construction
        self.goals: list[Goal] = []

    @abc.abstractmethod
    def exposes(self, action_space: Any) -> frozenset[str]:
        """Which :class:`PolicyOutput` fields this recognizer fills for ``action_space``."""

    @abc.abstractmethod
    def policy_output(self, observed: Any) -> tuple[PolicyOutput, np.ndarray]:
        """Outputs of every goal's policy on the observed states, and the observed actions."""

    def check_scorer(self, name: str, action_space: Any) -> Scorer:
        """The scorer ``name`` if this recognizer can serve it; a clear error otherwise."""
        scorer = get_scorer(name)
        exposes = self.exposes(action_space)
        if not scorer.can_serve(exposes):
            offered = ", ".join(sorted(exposes)) or "nothing"
            raise ValueError(f"scorer {name!r} needs {scorer.needs_text()}; recognizer {self.name!r} "
                             f"exposes only {offered} on this action space")
        return scorer

    def score(self, observed: Any) -> dict[Goal, float]:
        """Scores of every goal under :attr:`scorer` (see :class:`grail_bench.Recognizer`)."""
        return self.score_with(observed, self.scorer)

    def score_with(self, observed: Any, scorer: str) -> dict[Goal, float]:
        """Scores of every goal under the named scorer."""
        output, actions = self.policy_output(observed)
        chosen = get_scorer(scorer)
        if not chosen.can_serve(output.exposes()):
            raise ValueError(f"scorer {scorer!r} needs {chosen.needs_text()}; recognizer {self.name!r} "
                             f"exposes only {', '.join(sorted(output.exposes()))}")
        return dict(zip(self.goals, chosen.fn(output, actions).tolist()))
