"""Recognizers whose score is a pluggable scorer over their goal policies' outputs."""

from __future__ import annotations

import abc
import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from gymnasium import spaces

from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Demos, EnvFactory, Goal
from grail_bench.recognizers.contract import (
    FitDiagnostics,
    NotFittedError,
    RecognizerBase,
    checked_settings,
    observed_arrays,
)
from grail_bench.recognizers.diagnostics import policy_diagnostics
from grail_bench.recognizers.evidence import Evidence, domain_noop
from grail_bench.recognizers.scoring import PolicyOutput, Scorer, check_served, get_scorer

#: How a continuous policy's predicted action meets its env's action box when scored (:func:`action_box_setting`).
ActionBox = Literal["ignore", "clip"]


def action_box_setting() -> Any:
    """The ``action_box`` field of a settings dataclass (``action_box: ActionBox = action_box_setting()``).

    ``"ignore"`` (the default: the published method) scores a continuous policy's Gaussian mean as it is, which
    may lie outside the env's action box (a PPO agent trained on the env's reward often pushes it far past the
    bounds the env clips its actions to); ``"clip"`` scores the mean clipped to the box, the action SB3's
    deterministic ``predict`` returns (the spread is kept). Left out of the configuration's key at its default, so
    earlier keys stay valid; scoring only (metadata ``scoring``), so cached models are shared across its values.
    """
    return field(default="ignore", metadata={"scoring": True, "omit_default": True})


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

    Knowing where the goals have evidence: a subclass whose :attr:`Config` has an ``off_support`` field
    (:func:`off_support_setting`, of type :data:`OffSupport`) calls :meth:`learn_evidence` with the training
    demonstrations in its ``fit``; scoring then replaces each goal's outputs at states off that goal's support
    (:class:`Evidence`) by the rule it names. Its default, ``"trust"``, scores the outputs as they are (the
    published methods). ``"stay"`` needs the domain's no-op action (the domain capability ``noop_action``): a
    task whose domain declares none is refused by :meth:`check_task` where the run is planned, before any
    training. A subclass that learns the evidence may also expose ``"occupancy"``: each goal's smoothed state
    occupancy in its training demonstrations, which the ``occupancy`` scorer adds to the policy's log-likelihood.
    A :attr:`Config` with an ``action_box`` field (:func:`action_box_setting`) may score continuous means clipped to
    the env's action box.

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
        self.config = checked_settings(self.Config, settings, self.name)
        self.default_scorer = scorer or type(self).default_scorer
        get_scorer(self.default_scorer)  # unknown names fail at construction
        self.goals: list[Goal] = []
        self.curves: dict[Goal, dict[str, list[float]]] = {}  # per goal, what its training logged
        self.observation_space: Any = None
        self.action_space: Any = None
        self.evidence: Evidence | None = None  # learnt by learn_evidence() at fit
        self._evidence_error = ""  # why it could not be learnt, if it could not

    @property
    def off_support(self) -> str:
        """The configured off-support rule (``"trust"`` for settings without one)."""
        return getattr(self.config, "off_support", "trust")

    @property
    def action_box(self) -> str:
        """How a continuous mean meets the action box when scored (``"ignore"`` for settings without it)."""
        return getattr(self.config, "action_box", "ignore")

    def noop_settings(self) -> list[str]:
        """The settings, as ``name='value'``, that need the domain's no-op action (subclasses add theirs)."""
        return ["off_support='stay'"] if self.off_support == "stay" else []

    def check_task(self, task: Any) -> None:
        """Refuse a task whose domain cannot serve the settings (called where a run is planned, before training).

        Raises:
            UserError: In one line, when a setting needs the domain's no-op action and the domain declares none,
                or for ``action_box='clip'`` on actions that are not a bounded box.
        """
        self._refuse_without_noop(getattr(task.spec, "noop_action", None), f"domain {task.domain!r}")
        if self.action_box == "clip":
            self._check_action_box(task.action_space())

    def _check_action_box(self, action_space: Any) -> None:
        """Refuse ``action_box='clip'`` on actions that are not a bounded box.

        Raises:
            UserError: In one line.
        """
        if self.action_box == "clip" and not (isinstance(action_space, spaces.Box)
                                              and np.all(np.isfinite(action_space.low))
                                              and np.all(np.isfinite(action_space.high))):
            raise UserError(f"{self.name}: action_box='clip' needs a bounded continuous action box, got {action_space}")

    def _refuse_without_noop(self, noop: Any, domain: str) -> list[str]:
        """The settings that need the domain's no-op action (:meth:`noop_settings`), refused if ``noop`` is None.

        Raises:
            UserError: In one line naming those settings and ``domain``.
        """
        needs = self.noop_settings()
        if needs and noop is None:
            raise UserError(f"{self.name}: {' and '.join(needs)} needs the domain's no-op action; {domain} declares "
                            "no noop_action")
        return needs

    def learn_evidence(self, demos: Demos, env_factory: EnvFactory) -> Evidence | None:
        """Learn where each goal's training demonstrations went (:class:`Evidence`), keep it and return it.

        Called by ``fit`` before any training, so a setting the domain cannot serve fails first; it also sets the
        env's :attr:`observation_space` and :attr:`action_space`. On spaces the
        evidence cannot be learnt on, None, while no setting needs it (the ``occupancy`` scorer is refused then).

        Raises:
            UserError: When a setting needs the domain's no-op action and the env's task names no domain
                declaring one, or for ``off_support='uniform'`` or ``action_box='clip'`` on an unbounded action box
                (``action_box='clip'``: on discrete actions too).
        """
        env = env_factory(next(iter(demos)))
        try:
            observation_space, action_space, noop = env.observation_space, env.action_space, domain_noop(env)
        finally:
            env.close()
        self.observation_space, self.action_space = observation_space, action_space  # for keys made before training
        self._check_action_box(action_space)
        needs = self._refuse_without_noop(noop, "the env's domain")
        try:
            self.evidence, self._evidence_error = Evidence(demos, observation_space, action_space, noop), ""
        except UserError as exc:
            if needs or self.off_support != "trust":
                raise
            self.evidence, self._evidence_error = None, str(exc)  # nothing needs it yet: refused if asked for
            return None
        if self.off_support == "uniform" and isinstance(action_space, spaces.Box):
            self.evidence.replacement("uniform")
        return self.evidence

    @abc.abstractmethod
    def exposes(self, action_space: Any) -> frozenset[str]:
        """Which :class:`PolicyOutput` fields this recognizer fills for ``action_space``."""

    @abc.abstractmethod
    def outputs_at(self, states: np.ndarray) -> PolicyOutput:
        """Outputs of every goal's policy on ``(T, ...)`` states (already checked against the spaces)."""

    def ruled_outputs(self, states: np.ndarray) -> PolicyOutput:
        """:meth:`outputs_at` with the mean clipped to the action box (``action_box="clip"``) and the ``off_support``
        rule applied: what is scored."""
        output = self.outputs_at(states)
        if self.action_box == "clip":
            output = dataclasses.replace(output, mean=np.clip(output.mean, self.action_space.low,
                                                              self.action_space.high).astype(output.mean.dtype))
        if self.off_support != "trust":
            output = self._evidence().replace_off_support(output, self.goals, states, self.off_support)
        return output

    def policy_output(self, observed: Any, occupancy: bool = False) -> tuple[PolicyOutput, np.ndarray]:
        """Outputs of every goal's policy on the observed states, as scored, and the observed actions.

        The outputs are :meth:`outputs_at`'s, with the ``off_support`` rule applied; with ``occupancy``, also
        each goal's log occupancy at the states (:class:`Evidence`), where the recognizer exposes it.

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For an observation that does not fit the env's spaces.
        """
        if not self.goals:
            raise NotFittedError(f"{self.name}: call fit() before score()")
        states, actions = observed_arrays(observed, self.observation_space, self.action_space)
        output = self.ruled_outputs(states)
        if occupancy and "occupancy" in self.exposes(self.action_space):
            output = dataclasses.replace(output, log_occupancy=self._evidence().log_occupancy(self.goals, states))
        return output, actions

    def _scored(self, observed: Any, scorer: str | None) -> tuple[Scorer, PolicyOutput, np.ndarray]:
        """The scorer to use, the outputs it needs and the observed actions."""
        name = scorer or self.default_scorer
        chosen = get_scorer(name)
        output, actions = self.policy_output(observed, occupancy=any("occupancy" in need for need in chosen.needs))
        return check_served(chosen, output.exposes(), self.name, name), output, actions

    def _evidence(self) -> Evidence:
        if self.evidence is None:
            why = getattr(self, "_evidence_error", "") or ("off_support and the occupancy scorer need the goals' "
                                                           "training states; its fit must call learn_evidence()")
            raise UserError(f"{self.name}: {why}")
        return self.evidence

    def diagnose(self, train: Demos, held_out: Demos, env_factory: EnvFactory | None) -> FitDiagnostics:
        """Evidence about each goal's fitted policy (:mod:`grail_bench.recognizers.diagnostics`)."""
        return policy_diagnostics(self.outputs_at, self.goals, train, held_out, env_factory, self.curves)

    def score(self, observed: Any, scorer: str | None = None) -> dict[Goal, float]:
        """Scores of every goal (see :class:`~grail_bench.recognizers.contract.Recognizer`)."""
        chosen, output, actions = self._scored(observed, scorer)
        return dict(zip(self.goals, chosen.scores(output, actions, len(self.goals)).tolist()))

    def score_prefixes(self, observed: Any, scorer: str | None = None) -> dict[Goal, np.ndarray]:
        """Scores of every prefix ``k = 1..T`` of ``observed``, per goal a ``(T,)`` array, from one pass.

        Column ``k - 1`` equals :meth:`score` on the first ``k`` pairs: the
        policies are evaluated once on all ``T`` states and the scorer's
        per-step scores are accumulated.
        """
        chosen, output, actions = self._scored(observed, scorer)
        return dict(zip(self.goals, chosen.prefix_scores(output, actions, len(self.goals))))
