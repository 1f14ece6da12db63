"""The recognizer contract: two required methods, and capabilities a recognizer may declare.

Required, and all a plugin needs (:class:`Recognizer`)::

    class Mine:
        def fit(self, demos, env_factory=None, *, seed=0): ...   # demos: {goal: [Trajectory, ...]}
        def score(self, observed): ...                           # -> {goal: float}, higher = more likely

Optional: every member of :class:`OptionalCapabilities`, each an attribute or a method with a documented
default that applies when a recognizer does not declare it (:class:`RecognizerBase` gives the attributes
their defaults), and two extensions of the required methods (``score(observed, scorer)`` and
``fit(..., cache_key=...)``, see :class:`OptionalCapabilities`).

The demonstrations and observations are :class:`~grail_bench.core.trajectory.Trajectory` objects: training
demonstrations run to the task's fixed horizon (after the goal the agent stays there), observed ones are the
pairs an observation protocol picks, from the path up to the goal unless the protocol says otherwise (see
:mod:`grail_bench.core.trajectory`).

The harness never reads a recognizer directly: :func:`capabilities` reads
every optional member once, in this module, and returns a typed
:class:`Capabilities` through which the harness fits, scores and asks.
"""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping, Protocol, Sequence, runtime_checkable

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.params import check_kwargs
from grail_bench.core.spaces import check_within
from grail_bench.core.trajectory import Demos, EnvFactory, Goal
from grail_bench.task.observation import CHANNELS, observed_channel

if TYPE_CHECKING:
    from grail_bench.core.trajectory import Trajectory

#: The label of a recognizer's own scoring, when it serves no registered scorer.
OWN_SCORING = "default"
#: The channels of a recognizer that declares none.
DEFAULT_CHANNELS = frozenset({"pairs"})


class RecognizerError(UserError):
    """A recognizer broke the contract (e.g. returned scores for the wrong goals)."""


class NotFittedError(UserError, RuntimeError):
    """A recognizer asked to score (or to take new goals) before it was fitted.

    A :class:`~grail_bench.core.errors.UserError`, reported in one line; also a ``RuntimeError``, as it was
    before, so callers catching that keep working. Plugins raise it too (``"name: call fit() before score()"``).
    """


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
    """A goal recognizer: the two required methods, all a plugin needs (no base class).

    The optional members are those of :class:`OptionalCapabilities`. A recognizer is built with keyword
    arguments only (its hyperparameters, from ``--set name.field=value``), fitted once per task, seed and
    training split, then asked to score many observations.
    """

    def fit(self, demos: Demos, env_factory: EnvFactory | None = None, *, seed: int = 0) -> FitReport | None:
        """Prepare to recognise the goals of ``demos``.

        Args:
            demos: The training demonstrations of every candidate goal, ``{goal: [Trajectory, ...]}``, the
                same number per goal. Each runs to the task's fixed horizon: after the action that reached
                the goal (its info's ``is_success``) the agent stays there until the horizon, so cut them
                with :func:`~grail_bench.core.trajectory.until_success` to learn the behaviour up to the goal.
            env_factory: ``env_factory(goal)`` builds the domain env pursuing
                ``goal`` (for methods that learn from interaction).
            seed: Seed for everything random in fitting.

        Returns:
            What fitting cost, as a :class:`FitReport`; anything else (``None``, ``self``) lets the harness
            time the call.
        """
        ...

    def score(self, observed: Trajectory) -> Mapping[Goal, float]:
        """Score every goal given to :meth:`fit`; higher means more likely.

        Args:
            observed: ``k`` observed actions and the ``k + 1`` states around
                them; ``observed.acts[t]`` was taken in ``observed.obs[t]``
                (for a random subset, ``obs[k]`` follows the last pair). The
                pairs come from the path up to the goal (from the whole
                fixed-horizon episode under the ``horizon-*`` protocols); its
                ``infos`` are None, so it never carries the true goal. On the
                ``states`` channel its actions are NaN, on ``actions`` its
                states (see :attr:`OptionalCapabilities.channels`).

        Returns:
            One finite float per goal fitted (or given to ``set_goals``), keyed by the goals as given.
        """
        ...


class OptionalCapabilities(Protocol):
    """Every optional member a recognizer may declare, with the default that applies when it does not.

    Declare an attribute on the class (or the instance) or define a method to offer a capability; nothing
    needs to inherit from this class (it documents the members, and types them). The harness reads them once,
    through :func:`capabilities`, and calls only what a recognizer declares.

    Two capabilities extend the required methods rather than add members:

    * ``score(observed, scorer)``: a second positional argument, the name of the registered scorer to judge
      with (one that needs no policy output beyond what :meth:`exposes` gives; checked before any work).
      Default: the recognizer's own scoring only.
    * ``fit(demos, env_factory, *, seed, cache_key)``: the keyword ``cache_key``, a string naming the
      domain and its env parameters (not the regime), so models learnt from interaction alone can be cached
      across fits and regimes. Default: not passed.
    """

    name: str
    """The name it is registered under, for messages (the harness uses the registered name). Default:
    ``""``."""

    paper_name: str
    """The method's published name, shown by the leaderboard beside the values a paper reports. Default:
    the registered name."""

    reference: bool
    """``True`` for a reference rather than a method (what a method could reach, such as perfect imitation):
    shown beside the methods, never ranked. Default: ``False``."""

    config: Any
    """Its settings, a frozen dataclass or a mapping; they key stored results and cached models (see
    :func:`settings_key`). Default: the keyword arguments it was built with."""

    default_scorer: str
    """What :meth:`Recognizer.score` computes unless told otherwise: a registered scorer's name, or
    ``"default"`` (its own scoring). Default: ``"default"``."""

    channels: frozenset[str]
    """The observation channels ``score`` can use, a set of ``"pairs"`` (states and actions), ``"states"``
    (actions NaN) and ``"actions"`` (states NaN; see :mod:`grail_bench.task.observation`). A class attribute:
    it is read before anything is built, and a run on another channel is refused before any training.
    Default: ``{"pairs"}``."""

    def exposes(self, action_space: Any) -> frozenset[str]:
        """The policy outputs registered scorers may use on ``action_space``: names among ``"probs"``,
        ``"mean"``, ``"std"``, ``"q"`` and ``"occupancy"`` (see :class:`~grail_bench.recognizers.scoring.PolicyOutput`).
        Default: none (its own scoring only)."""
        ...

    def score_prefixes(self, observed: Trajectory, scorer: str | None = None) -> Mapping[Goal, np.ndarray]:
        """The scores of every prefix of ``observed`` from one pass (online mode): per goal a ``(T,)`` array
        whose entry ``k - 1`` is what ``score`` gives the first ``k`` pairs. Default: each prefix scored
        alone by ``score``."""
        ...

    def diagnose(self, train: Demos, held_out: Demos, env_factory: EnvFactory) -> FitDiagnostics | None:
        """Evidence about each goal's fitted model, after :meth:`Recognizer.fit`, on the training and held-out
        demonstrations (``grail-bench run --diagnostics``). Default: no diagnostics."""
        ...

    def set_goals(self, goals: Sequence[Goal]) -> None:
        """Score ``goals`` from now on, demonstrated in the fit or not (goal-conditioned models; needed by
        ``--mode zero-shot``). Default: only the goals it was fitted on."""
        ...

    def check_task(self, task: Any) -> None:
        """Refuse a task it cannot run as configured by raising a one-line
        :class:`~grail_bench.core.errors.UserError` (e.g. a setting needs a capability the task's domain
        lacks); ``task`` is a :class:`~grail_bench.task.model.GRTask`. Called where a run is planned, before
        any training. Default: every task accepted."""
        ...


class RecognizerBase:
    """An optional base class giving ``name``, ``paper_name``, ``reference``, ``default_scorer`` and ``exposes``
    (of :class:`OptionalCapabilities`) their defaults.

    Subclasses implement :meth:`fit` and :meth:`score` and override or add what they offer (the optional
    methods it leaves out are read as not offered).
    """

    name: str = ""
    paper_name: str = ""
    reference: bool = False
    default_scorer: str = OWN_SCORING

    def exposes(self, action_space: Any) -> frozenset[str]:
        """Policy outputs registered scorers may use (none: own scoring only)."""
        return frozenset()

    def fit(self, demos: Demos, env_factory: EnvFactory | None = None, *, seed: int = 0) -> FitReport | None:
        raise NotImplementedError

    def score(self, observed: Trajectory) -> Mapping[Goal, float]:
        raise NotImplementedError


@dataclass(frozen=True)
class FitDiagnostics:
    """Evidence about each goal's fitted model, in the order of the goals fitted (read-only: nothing selects on it).

    Attributes:
        goals: The goals, as fitted.
        agreement_train: Per goal, the share of its training demonstrations' actions the model's greedy
            action matches (continuous actions: the share within the demonstrations' noise of the mean).
        agreement_held_out: The same on its held-out demonstrations (None where there are none).
        imitation: ``(K, K)``: entry ``[i, j]`` is the mean probability (discrete) or likelihood per step
            (continuous) of goal ``i``'s demonstrated actions under goal ``j``'s model.
        reached: Per goal, whether the model's greedy rollout from the task's start reaches the goal.
        rollout_length: Per goal, the greedy rollout's steps up to the goal (its whole length if it never does).
        demo_length: Per goal, the mean steps its demonstrations take to the goal.
        curves: Training curves the libraries log, per goal (``{goal index: {name: [values]}}``), kept short.
    """

    goals: tuple[Goal, ...]
    agreement_train: tuple[float, ...]
    agreement_held_out: tuple[float | None, ...]
    imitation: tuple[tuple[float, ...], ...]
    reached: tuple[bool | None, ...]
    rollout_length: tuple[int | None, ...]
    demo_length: tuple[float, ...]
    curves: Mapping[int, Mapping[str, Sequence[float]]] = field(default_factory=dict)


def _accepts(method: Callable[..., Any], name: str, positional: int = 0) -> bool:
    """Whether ``method`` takes keyword ``name`` (or ``positional`` positional arguments besides the first)."""
    try:
        params = inspect.signature(method).parameters.values()
    except (TypeError, ValueError):
        return False
    if any(p.kind is p.VAR_KEYWORD for p in params) and positional == 0:
        return True
    if positional:
        count = sum(p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) for p in params)
        return count > positional or any(p.kind is p.VAR_POSITIONAL for p in params)
    return any(p.name == name and p.kind is not p.POSITIONAL_ONLY for p in params)


@dataclass(frozen=True)
class Info:
    """What a recognizer class says of itself, read without building one.

    Attributes:
        name: The registered name.
        paper_name: The method's published name (``name`` when it declares none).
        default_scorer: What it scores with unless told otherwise.
        reference: Whether it is a reference rather than a method (shown beside methods, never ranked).
        channels: The observation channels its ``score`` can use.
    """

    name: str
    paper_name: str
    default_scorer: str
    reference: bool = False
    channels: frozenset[str] = DEFAULT_CHANNELS

    def check_channel(self, channel: str) -> None:
        """Refuse an observation channel the recognizer does not declare.

        Raises:
            RecognizerError: In one line, naming the channels it can use.
        """
        if channel not in self.channels:
            raise RecognizerError(f"{self.name} cannot use the {channel} channel: it scores "
                                  f"{', '.join(c for c in CHANNELS if c in self.channels)} only (its channels "
                                  "capability)")


def _channels(obj: Any, name: str) -> frozenset[str]:
    """The channels a recognizer class or instance declares (``{"pairs"}`` when it declares none)."""
    declared = getattr(obj, "channels", None)
    if declared is None:
        return DEFAULT_CHANNELS
    if isinstance(declared, str) or not isinstance(declared, (set, frozenset, list, tuple)) \
            or not declared or not set(declared) <= set(CHANNELS):
        raise RecognizerError(f"recognizer {name!r}: channels must be a non-empty set of {', '.join(CHANNELS)}, "
                              f"got {declared!r}")
    return frozenset(declared)


def info(obj: Any, name: str) -> Info:
    """The :class:`Info` of a recognizer class or instance registered as ``name``.

    Raises:
        RecognizerError: For ``channels`` naming an unknown channel.
    """
    paper = getattr(obj, "paper_name", "")
    scorer = getattr(obj, "default_scorer", OWN_SCORING)
    return Info(name=name, paper_name=paper if isinstance(paper, str) and paper else name,
                default_scorer=scorer if isinstance(scorer, str) and scorer else OWN_SCORING,
                reference=getattr(obj, "reference", False) is True, channels=_channels(obj, name))


@dataclass(frozen=True)
class Capabilities:
    """A recognizer as the harness sees it: its declared capabilities, read once, and calls that use them.

    Build it with :func:`capabilities`; each optional member is documented in :class:`OptionalCapabilities`.

    Attributes:
        recognizer: The recognizer object.
        info: What its class says of itself (names, default scorer, reference, channels).
        config: Its settings as the plain dict that keys stored results (:func:`settings_key`).
        kwargs: The keyword arguments it was built with.
        takes_scorer: Its ``score`` takes a registered scorer as a second argument.
        takes_cache_key: Its ``fit`` takes ``cache_key``.
        has_prefix_scores: It has ``score_prefixes``.
        has_diagnostics: It has ``diagnose``.
        has_set_goals: It has ``set_goals``.
        has_check_task: It has ``check_task``.
    """

    recognizer: Any
    info: Info
    config: Mapping[str, Any]
    kwargs: Mapping[str, Any]
    takes_scorer: bool
    takes_cache_key: bool
    has_prefix_scores: bool
    has_diagnostics: bool
    has_set_goals: bool = False
    has_check_task: bool = False

    @property
    def name(self) -> str:
        """The name it is registered under."""
        return self.info.name

    @property
    def channels(self) -> frozenset[str]:
        """The observation channels ``score`` can use."""
        return self.info.channels

    @property
    def default_scorer(self) -> str:
        """What ``score`` computes unless told otherwise (``"default"``: its own scoring)."""
        return self.info.default_scorer

    def exposes(self, action_space: Any) -> frozenset[str]:
        """Policy outputs registered scorers may use on ``action_space`` (none without ``exposes``)."""
        method = getattr(self.recognizer, "exposes", None)
        if method is None:
            return frozenset()
        out = method(action_space)
        if not isinstance(out, (set, frozenset)) or not all(isinstance(x, str) for x in out):
            raise RecognizerError(f"recognizer {self.name!r}: exposes() must return a set of output names")
        return frozenset(out)

    def fit(self, demos: Demos, env_factory: EnvFactory, seed: int, cache_key: str | None) -> FitReport | None:
        """``fit`` with the cache key when the recognizer takes one; its :class:`FitReport`, or None when it
        returns anything else (``None``, ``self``, ...)."""
        extra = {"cache_key": cache_key} if self.takes_cache_key else {}
        report = self.recognizer.fit(demos, env_factory, seed=seed, **extra)
        return report if isinstance(report, FitReport) else None

    def score(self, observed: Trajectory, scorer: str | None = None) -> Mapping[Goal, float]:
        """``score`` with a registered scorer, or the recognizer's own scoring when ``scorer`` is None."""
        if scorer is None:
            return self.recognizer.score(observed)
        if not self.takes_scorer:
            raise RecognizerError(f"recognizer {self.name!r} scores with its own scoring only")
        return self.recognizer.score(observed, scorer)

    def score_prefixes(self, observed: Trajectory, scorer: str | None = None) -> Mapping[Goal, np.ndarray] | None:
        """Scores of every prefix from one pass, or None when the recognizer cannot give them."""
        if not self.has_prefix_scores:
            return None
        return self.recognizer.score_prefixes(observed, scorer)

    def set_goals(self, goals: Sequence[Goal]) -> None:
        """Make the recognizer score ``goals`` from now on, fitted or not.

        Raises:
            RecognizerError: If it cannot score goals it was not fitted on.
        """
        if not self.has_set_goals:
            raise RecognizerError(f"recognizer {self.name!r} scores only the goals it was fitted on (it has no "
                                  "set_goals)")
        self.recognizer.set_goals(list(goals))

    def check_task(self, task: Any) -> None:
        """Let the recognizer refuse ``task`` before any training (nothing happens when it has no ``check_task``).

        Raises:
            grail_bench.core.errors.UserError: What the recognizer raises, in one line.
        """
        if self.has_check_task:
            self.recognizer.check_task(task)

    def diagnose(self, train: Demos, held_out: Demos, env_factory: EnvFactory) -> FitDiagnostics | None:
        """The recognizer's fit diagnostics, or None when it offers none."""
        if not self.has_diagnostics:
            return None
        out = self.recognizer.diagnose(train, held_out, env_factory)
        if out is not None and not isinstance(out, FitDiagnostics):
            raise RecognizerError(f"recognizer {self.name!r}: diagnose() must return FitDiagnostics or None")
        return out


def checked_settings(config_class: type, settings: Mapping[str, Any], name: str) -> Any:
    """A recognizer's settings dataclass built from keywords, each checked against its field's type first.

    Args:
        config_class: The frozen settings dataclass (a recognizer's ``Config``).
        settings: The keywords given (e.g. from ``--set name.field=value``).
        name: The recognizer's registered name, which every message starts with.

    Raises:
        UserError: For an unknown setting, or a value of the wrong type or refused by the dataclass's own checks.
    """
    checked = check_kwargs(config_class, settings, f"recognizer {name!r}")
    try:
        return config_class(**checked)
    except UserError as exc:
        raise UserError(f"recognizer {name!r}: {exc}") from None


def settings_key(settings: Any, *, models: bool = False) -> dict[str, Any]:
    """A recognizer's settings as the plain dict that keys its stored results and cached models.

    A settings dataclass gives its fields (tuples as lists, as JSON reads them back), less those whose
    metadata says ``omit_none`` while they are None, or ``omit_default`` while they equal their default
    (settings added later, so earlier keys stay valid); a mapping is taken as it is.

    Args:
        settings: A settings dataclass or a mapping.
        models: Key cached models rather than stored results: fields whose metadata says ``scoring`` (they
            change how fitted models are read, not what is fitted, e.g. ``off_support``) are left out, so
            configurations that differ only there share their trained models.
    """
    if dataclasses.is_dataclass(settings) and not isinstance(settings, type):
        values = {}
        for f in dataclasses.fields(settings):
            value = getattr(settings, f.name)
            if f.metadata.get("omit_none") and value is None:
                continue
            if f.metadata.get("omit_default") and f.default is not dataclasses.MISSING and value == f.default:
                continue
            if models and f.metadata.get("scoring"):
                continue
            values[f.name] = value
        return {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}
    return dict(settings)


def capabilities(recognizer: Any, name: str, kwargs: Mapping[str, Any] | None = None) -> Capabilities:
    """Read a recognizer's capabilities, once (see the module docstring for each default).

    Args:
        recognizer: An object with ``fit`` and ``score``.
        name: The name it is registered under.
        kwargs: The keyword arguments it was built with (its config when it declares none).

    Raises:
        RecognizerError: If ``fit`` or ``score`` is missing, ``config`` is not a mapping, or ``channels`` names
            an unknown channel.
    """
    missing = [m for m in ("fit", "score") if not callable(getattr(recognizer, m, None))]
    if missing:
        raise RecognizerError(f"recognizer {name!r} ({type(recognizer).__name__}) does not satisfy the recognizer "
                              f"contract: it lacks {' and '.join(missing)} (see grail_bench.Recognizer)")
    config = getattr(recognizer, "config", None)
    if config is None:
        config = dict(kwargs or {})
    if not isinstance(config, Mapping) and not dataclasses.is_dataclass(config):
        raise RecognizerError(f"recognizer {name!r}: config must be a dataclass or a mapping, got "
                              f"{type(config).__name__}")
    return Capabilities(
        recognizer=recognizer, info=info(recognizer, name), config=settings_key(config), kwargs=dict(kwargs or {}),
        takes_scorer=_accepts(recognizer.score, "scorer", positional=1),
        takes_cache_key=_accepts(recognizer.fit, "cache_key"),
        has_prefix_scores=callable(getattr(recognizer, "score_prefixes", None)),
        has_diagnostics=callable(getattr(recognizer, "diagnose", None)),
        has_set_goals=callable(getattr(recognizer, "set_goals", None)),
        has_check_task=callable(getattr(recognizer, "check_task", None)),
    )


def observed_arrays(observed: Any, observation_space: Any, action_space: Any,
                    channels: frozenset[str] = DEFAULT_CHANNELS) -> tuple[np.ndarray, np.ndarray]:
    """Validate an observed trajectory against the env's spaces and return its ``(states, actions)`` pairs.

    Args:
        observed: An ``imitation`` ``Trajectory`` (or anything with ``obs`` and ``acts``).
        observation_space: The space each state must belong to.
        action_space: The space each action must belong to.
        channels: The channels the caller can use (its ``channels`` capability): an observation on one of them
            has the part it hides (NaN) left unchecked; on any other channel NaN is a value outside its space.

    Returns:
        ``(obs[:k], acts)``: the ``k`` states in which the ``k`` actions were taken.

    Raises:
        UserError: For an empty prefix, mismatched lengths, wrong shapes, values outside a space (NaN included,
            unless hidden by one of ``channels``) or an observation on a channel the caller cannot use.
    """
    try:
        obs, acts = np.asarray(observed.obs), np.asarray(observed.acts)
    except AttributeError:
        raise UserError(f"expected a Trajectory with obs and acts, got {type(observed).__name__}") from None
    if len(acts) == 0:
        raise UserError("the observed trajectory is empty: at least one action is needed")
    if len(obs) != len(acts) + 1:
        raise UserError(f"malformed trajectory: {len(obs)} states for {len(acts)} actions (need actions + 1)")
    if obs.shape[1:] != observation_space.shape:
        raise UserError(f"observed states have shape {obs.shape[1:]}, the env's are {observation_space.shape} "
                        f"({observation_space})")
    if acts.shape[1:] != action_space.shape:
        raise UserError(f"observed actions have shape {acts.shape[1:]}, the env's are {action_space.shape} "
                        f"({action_space})")
    channel = observed_channel(observed)
    if channel != "pairs" and channel not in channels:
        raise UserError(f"this observation carries {channel} only; scoring it needs {' or '.join(sorted(channels))}")
    states = obs[: len(acts)]
    if channel != "actions":
        check_within(states, observation_space, "observed states")
    if channel != "states":
        check_within(acts, action_space, "observed actions")
    return states, acts
