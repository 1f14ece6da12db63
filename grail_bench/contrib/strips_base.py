"""What the planning-based recognizers share: a symbolic task's grounded model, and observed actions as its operators.

:class:`StripsRecognizer` is the base of recognizers that reason on the STRIPS model of a symbolic
(PDDL/STRIPS) task rather than learn from demonstrations (``prp``, ``landmarks``). It refuses any other task
in one line where a run is planned (``check_task``), reads the model and each candidate goal's state mask from
``env_factory(goal).unwrapped`` in ``fit`` (the demonstrations are not read: only their goals are), and turns
an observed trajectory into the observed operator indices (the actions channel: states may be NaN).
"""

from __future__ import annotations

from typing import Any, ClassVar, Sequence

from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Demos, EnvFactory, Goal
from grail_bench.domains.symbolic.strips import StripsModel
from grail_bench.recognizers.contract import NotFittedError, RecognizerBase, checked_settings, observed_arrays

DOMAIN = "symbolic"


class StripsRecognizer(RecognizerBase):
    """Base of recognizers scoring candidate goals on a symbolic task's grounded STRIPS model.

    A subclass sets :attr:`Config` (a frozen dataclass of its settings) and implements :meth:`score`, reading
    :attr:`model`, :attr:`goals` and :attr:`goal_masks` (set by :meth:`fit` and :meth:`set_goals`, which then
    call :meth:`fitted`) and :meth:`observed_operators`. Nothing is learnt per goal, so it scores any candidate
    goal of the fitted task (``set_goals``: zero-shot goals).

    Args:
        **settings: Fields of :attr:`Config`.

    Raises:
        UserError: For an unknown setting, or a value of the wrong type or out of range.
    """

    Config: ClassVar[type]
    channels = frozenset({"pairs", "actions"})

    def __init__(self, **settings: Any) -> None:
        self.config = checked_settings(self.Config, settings, self.name)
        self.model: StripsModel | None = None
        self.goals: list[Goal] = []
        self.goal_masks: list[int] = []
        self._factory: EnvFactory | None = None

    def check_task(self, task: Any) -> None:
        """Refuse, before anything is built, a task of another domain than the symbolic one.

        Raises:
            UserError: In one line, naming the task and its domain.
        """
        domain = getattr(task, "domain", None)
        if domain != DOMAIN:
            raise UserError(f"{self.name}: {getattr(task, 'id', task)} is a {domain} task; it recognises goals of "
                            f"{DOMAIN} (PDDL/STRIPS) tasks only, on their grounded model")

    def fit(self, demos: Demos, env_factory: EnvFactory | None = None, *, seed: int = 0) -> None:
        """Read the grounded model and every goal's state mask from ``env_factory`` (no demonstration is read).

        Raises:
            UserError: Without goals or an env factory, or when the envs carry no grounded STRIPS model (a
                task of another domain).
        """
        if env_factory is None or not demos:
            raise UserError(f"{self.name}: fit needs the candidate goals and an env_factory building their envs")
        self._read([tuple(g) for g in demos], env_factory)
        self._factory = env_factory

    def set_goals(self, goals: Sequence[Goal]) -> None:
        """Score ``goals`` from now on (any hypotheses of the fitted task: nothing is learnt per goal).

        Raises:
            NotFittedError: Before :meth:`fit`.
        """
        if self._factory is None:
            raise NotFittedError(f"{self.name}: call fit() before set_goals()")
        self._read([tuple(g) for g in goals], self._factory)

    def _read(self, goals: list[Goal], env_factory: EnvFactory) -> None:
        """Read the model and each goal's state mask from its env, then :meth:`fitted`."""
        model, masks = None, []
        for goal in goals:
            env = env_factory(goal)
            try:
                inner = env.unwrapped
                found, mask = getattr(inner, "model", None), getattr(inner, "goal_mask", None)
                self.observation_space, self.action_space = env.observation_space, env.action_space
            finally:
                env.close()
            if not isinstance(found, StripsModel) or not isinstance(mask, int):
                raise UserError(f"{self.name}: the env of goal {list(goal)} carries no grounded STRIPS model; it "
                                f"recognises goals of {DOMAIN} (PDDL/STRIPS) tasks only")
            if model is not None and found is not model and found != model:
                raise UserError(f"{self.name}: the candidate goals' envs ground different problems")
            model = found
            masks.append(mask)
        self.model, self.goals, self.goal_masks = model, goals, masks
        self.fitted()

    def fitted(self) -> None:
        """Prepare what scoring needs once the model and goals are read (nothing by default)."""

    def observed_operators(self, observed: Any) -> list[int]:
        """The observed actions as operator indices of :attr:`model` (the states are not read).

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For something that is no trajectory, an empty one, mismatched lengths, or actions that
                are no operators of the model (NaN included: a states-only observation).
        """
        if self.model is None:
            raise NotFittedError(f"{self.name}: call fit() before score()")
        _, acts = observed_arrays(observed, self.observation_space, self.action_space, self.channels)
        return [int(a) for a in acts]
