"""Recognizers whose score is a pluggable scorer over their goal policies' outputs."""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.params import check_kwargs
from grail_bench.core.trajectory import Demos, EnvFactory, Goal
from grail_bench.recognizers.contract import FitDiagnostics, RecognizerBase, observed_arrays
from grail_bench.recognizers.diagnostics import policy_diagnostics
from grail_bench.recognizers.scoring import PolicyOutput, check_scorer, get_scorer


class NotFittedError(UserError, RuntimeError):
    """A recognizer asked to score (or to take new goals) before it was fitted.

    A :class:`~grail_bench.core.errors.UserError`, reported in one line; also a ``RuntimeError``, as it was
    before, so callers catching that keep working.
    """


@dataclass(frozen=True)
class NoSettings:
    """The settings of a recognizer that has none."""


class ScoredRecognizer(RecognizerBase, abc.ABC):
    """Base of recognizers that expose :class:`~grail_bench.recognizers.scoring.PolicyOutput`.

    A subclass declares its settings as a frozen dataclass, :attr:`Config`, and is built from keywords::

        BCRecognizer(n_epochs=50, scorer="loglik")   # self.config == BCRecognizer.Config(n_epochs=50)

    The settings are checked against the dataclass's field types (a value given as JSON, ``1e3`` for an
    integer, is converted where it can be) and by its own validation; they key stored results and cached
    models (:func:`~grail_bench.recognizers.contract.settings_key`). ``scorer`` is not a setting: it changes
    how a fitted model is read, not what is fitted.

    Subclasses say what they expose for an action space and compute the
    outputs on states (:meth:`outputs_at`); scoring is then any registered
    scorer that can work from those outputs, every prefix of an observation
    is scored from one pass (:meth:`score_prefixes`), and the fit is
    diagnosed from the same outputs (:meth:`diagnose`).

    Args:
        scorer: What :meth:`score` uses when no scorer is named; defaults to
            the class's :attr:`default_scorer` (the method's published one).
        **settings: Fields of :attr:`Config`.

    Raises:
        UserError: For an unknown setting, a value of the wrong type or out of range, or an unknown scorer.
    """

    name: str = ""
    paper_name: str = ""
    default_scorer: str = "mse"
    Config: ClassVar[type] = NoSettings

    def __init__(self, scorer: str | None = None, **settings: Any) -> None:
        checked = check_kwargs(self.Config, settings, f"recognizer {self.name!r}")
        try:
            self.config = self.Config(**checked)
        except UserError as exc:
            raise UserError(f"recognizer {self.name!r}: {exc}") from None
        self.default_scorer = scorer or type(self).default_scorer
        get_scorer(self.default_scorer)  # unknown names fail at construction
        self.goals: list[Goal] = []
        self.curves: dict[Goal, dict[str, list[float]]] = {}  # per goal, what its training logged
        self.observation_space: Any = None
        self.action_space: Any = None

    @abc.abstractmethod
    def exposes(self, action_space: Any) -> frozenset[str]:
        """Which :class:`PolicyOutput` fields this recognizer fills for ``action_space``."""

    @abc.abstractmethod
    def outputs_at(self, states: np.ndarray) -> PolicyOutput:
        """Outputs of every goal's policy on ``(T, ...)`` states (already checked against the spaces)."""

    def policy_output(self, observed: Any) -> tuple[PolicyOutput, np.ndarray]:
        """Outputs of every goal's policy on the observed states, and the observed actions.

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For an observation that does not fit the env's spaces.
        """
        if not self.goals:
            raise NotFittedError(f"{self.name}: call fit() before score()")
        states, actions = observed_arrays(observed, self.observation_space, self.action_space)
        return self.outputs_at(states), actions

    def diagnose(self, train: Demos, held_out: Demos, env_factory: EnvFactory | None) -> FitDiagnostics:
        """Evidence about each goal's fitted policy (:mod:`grail_bench.recognizers.diagnostics`)."""
        return policy_diagnostics(self.outputs_at, self.goals, train, held_out, env_factory, self.curves)

    def score(self, observed: Any, scorer: str | None = None) -> dict[Goal, float]:
        """Scores of every goal (see :class:`~grail_bench.recognizers.contract.Recognizer`)."""
        output, actions = self.policy_output(observed)
        chosen = check_scorer(scorer or self.default_scorer, output.exposes(), self.name)
        return dict(zip(self.goals, chosen.fn(output, actions).tolist()))

    def score_prefixes(self, observed: Any, scorer: str | None = None) -> dict[Goal, np.ndarray]:
        """Scores of every prefix ``k = 1..T`` of ``observed``, per goal a ``(T,)`` array, from one pass.

        Column ``k - 1`` equals :meth:`score` on the first ``k`` pairs: the
        policies are evaluated once on all ``T`` states and the scorer's
        per-step scores are accumulated.
        """
        output, actions = self.policy_output(observed)
        chosen = check_scorer(scorer or self.default_scorer, output.exposes(), self.name)
        return dict(zip(self.goals, chosen.prefix_scores(output, actions)))
