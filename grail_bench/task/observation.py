"""What a recognizer observes: observability levels and named observation protocols.

A protocol says which ``k`` state-action pairs of a test demonstration a
recognizer sees at observability ``p``. Built-in protocols:

* ``subset``: an ordered random subset of the path up to the goal (the
  baselines' gr_libs ``random_subset_with_order`` with ``is_consecutive=False``);
* ``prefix``: the first ``k`` pairs of the path up to the goal;
* ``horizon-subset`` and ``horizon-prefix``: the same over the whole padded
  fixed-horizon episode. Steps after the goal sit on the goal cell (the agent
  is absorbed there), so these protocols leak the goal.

``k = max(1, ceil(p * T))`` (``rounding="ceil"``) or ``max(1, floor(p * T))``
(``rounding="floor"``, gr_libs' ``int(p * T)``), ``T`` being the length of the
span. More protocols come from the entry-point group ``grail_bench.protocols``,
each an :class:`ObservationProtocol` (or any object with ``name``,
``description``, ``leaks_goal`` and ``select``).

Two observation models apply on top of any protocol, in every domain, with no domain code:

* **noise** (:func:`corrupt`): of the ``k`` observed steps, ``m = round(noise * k)``
  (nearest, halves up; :func:`n_spurious`) distinct steps drawn uniformly are
  *spurious*: the state is kept and the action replaced by one drawn uniformly
  from the action space's other actions (``Discrete``), or uniformly in the box
  (``Box``; another action with probability 1) (:class:`SpuriousActions`). The
  states that follow are untouched: a spurious step is a wrong observation, not
  another trajectory. Draws come from the cell's stream, after the protocol's.
* **channel** (:func:`project`): ``pairs`` (states and actions, the default),
  ``states`` or ``actions``. A recognizer still gets a ``Trajectory``
  of ``k`` actions and ``k + 1`` states, so every shape and index it knows keeps
  its meaning; the hidden channel is NaN (as floats): ``states`` keeps
  ``obs[:k]``, the states the observed steps were taken in, and blanks the
  actions and ``obs[k]`` (the successor would give the last action away);
  ``actions`` keeps ``acts`` and blanks every state. A states-channel
  recognizer reads ``obs[:k]``, ``k = len(acts)``, as every recognizer reads
  the states of the observed steps. NaN rather than a wrapper type: code
  written for pairs fails loudly on it (the spaces' checks refuse NaN, and a
  NaN score is refused), never silently. Only a recognizer that
  declares the channel (its ``channels`` capability) is given it;
  :func:`observed_channel` says which channel an observation carries.

The store labels them after the protocol and rounding: ``subset+noise0.2``,
``subset+floor+noise0.2``, ``prefix+states`` (:func:`protocol_label`,
:func:`parse_label`); labels without them are unchanged.

:data:`PROFILES` names observation set-ups of other toolkits: ``gr_libs``
(fractions 0.3 / 0.5 / 0.7 / 0.9 / 1.0, ``int(p * T)`` pairs, consecutive or
not: the ``prefix`` and ``subset`` protocols with ``floor`` rounding). gr_libs
observes 0 pairs where ``int(p * T)`` is 0 (``T < 4`` at 0.3); grail-bench
keeps one. At 0.7 and ``T`` in 90, 170, 180, 330, ... gr_libs' ``int(0.7 * T)``
truncates a floating-point product just below a whole number (``int(0.7 * 90)``
is 62); grail-bench observes the exact ``floor(0.7 * T)`` (63).
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass, field, replace
from typing import Any, Hashable, Iterable, Iterator, NamedTuple, Protocol, Sequence, runtime_checkable

import numpy as np

from grail_bench.core.registry import Registry
from grail_bench.core.errors import UserError
from grail_bench.core.seeding import cell_rng
from grail_bench.core.trajectory import Trajectory, goal_horizon

GROUP = "grail_bench.protocols"
ROUNDINGS = ("ceil", "floor")
CHANNELS = ("pairs", "states", "actions")
LEGACY_NAMES = {"random": "subset"}  # the deprecated ``--sampling random``
LEVEL_DECIMALS = 6  # levels are stored, and key their cells' random streams, to this many decimals


def level_text(level: float) -> str:
    """How an observability level reads in tables: a percentage to the precision levels are stored at
    (``10%``, ``2%``, ``0.1%``), so two stored levels never read the same."""
    return f"{round(level * 100, LEVEL_DECIMALS - 2):g}%"


def parse_observability(values: Iterable[float] | str) -> tuple[float, ...]:
    """Validate observability fractions (accepts ``"0.1,0.2"``), rounded to :data:`LEVEL_DECIMALS` decimals.

    Raises:
        ValueError: Unless every value is a number in (0, 1] that is not 0 at that precision, and no two
            different values are the same level at it.
    """
    items = values.split(",") if isinstance(values, str) else list(values)
    out: dict[float, float] = {}  # level as stored -> the value given
    for item in items:
        try:
            p = float(item)
        except (TypeError, ValueError):
            raise UserError(f"observability {item!r} is not a number") from None
        if not 0.0 < p <= 1.0 or math.isnan(p):
            raise UserError(f"observability {p:g} must be a fraction in (0, 1]")
        level = round(p, LEVEL_DECIMALS)
        if level == 0.0:
            raise UserError(f"observability {p} is 0 at the {LEVEL_DECIMALS} decimals levels are stored to")
        if out.setdefault(level, p) != p:
            raise UserError(f"observabilities {out[level]} and {p} are the same level, {level}, at the "
                            f"{LEVEL_DECIMALS} decimals levels are stored to")
    if not out:
        raise UserError("at least one observability level is needed")
    return tuple(out)


@dataclass(frozen=True)
class Selection:
    """Which pairs a protocol observes: from which span, and how.

    Attributes:
        horizon: Sample from the padded fixed-horizon episode (else the path up to the goal).
        random_subset: An ordered random subset (else the first ``k``).
        level: Observability fraction.
        rounding: ``"ceil"`` or ``"floor"``.
    """

    horizon: bool
    random_subset: bool
    level: float
    rounding: str = "ceil"

    def observations(self, pairs: Sequence[Hashable]) -> Iterator[tuple[tuple, float]]:
        """Every observation of a span of pairs with its probability (all ordered subsets, or the prefix)."""
        k = n_observed(self.level, len(pairs), self.rounding)
        if not self.random_subset:
            yield tuple(pairs[:k]), 1.0
            return
        weight = 1.0 / math.comb(len(pairs), k)
        for idx in itertools.combinations(range(len(pairs)), k):
            yield tuple(pairs[i] for i in idx), weight

    def sample(self, pairs: Sequence[Hashable], rng: np.random.Generator) -> tuple:
        """One observation of a span of pairs, drawn as the harness draws it."""
        k = n_observed(self.level, len(pairs), self.rounding)
        idx = np.sort(rng.choice(len(pairs), size=k, replace=False)) if self.random_subset else range(k)
        return tuple(pairs[i] for i in idx)


def _check_rounding(rounding: str) -> None:
    if rounding not in ROUNDINGS:
        raise UserError(f"unknown rounding {rounding!r}; choose one of {', '.join(ROUNDINGS)}")


def n_observed(fraction: float, length: int, rounding: str = "ceil") -> int:
    """How many pairs of a ``length``-step span are observed at ``fraction`` (at least 1, at most ``length``)."""
    _check_rounding(rounding)
    raw = round(fraction * length, 9)  # 0.3 * 10 is 3.0000000000000004 in floating point
    k = math.ceil(raw) if rounding == "ceil" else math.floor(raw)
    return min(length, max(1, k))


@runtime_checkable
class ProtocolLike(Protocol):
    """What the harness needs of an observation protocol."""

    name: str
    description: str
    leaks_goal: bool

    def select(self, traj: Trajectory, fraction: float, rng: np.random.Generator,
               rounding: str = "ceil") -> np.ndarray:
        """Sorted indices of the observed state-action pairs."""


@dataclass(frozen=True)
class ObservationProtocol:
    """A built-in protocol: a span of the demonstration and how pairs are picked from it.

    Attributes:
        name: Registry name, e.g. ``"subset"``.
        description: One line for ``grail-bench protocols``.
        span: ``"goal"`` (the path up to reaching the goal) or ``"horizon"``
            (every step of the fixed-horizon episode).
        random_subset: Pick an ordered random subset (else the first ``k``).
        leaks_goal: Whether observations can include steps after the goal.
    """

    name: str
    description: str
    span: str
    random_subset: bool
    leaks_goal: bool = False

    def length(self, traj: Trajectory) -> int:
        """Steps the protocol samples from."""
        return goal_horizon(traj) if self.span == "goal" else len(traj.acts)

    def select(self, traj: Trajectory, fraction: float, rng: np.random.Generator,
               rounding: str = "ceil") -> np.ndarray:
        """Sorted indices of the observed pairs; draws from ``rng`` only for random subsets."""
        length = self.length(traj)
        k = n_observed(fraction, length, rounding)
        if not self.random_subset:
            return np.arange(k)
        return np.sort(rng.choice(length, size=k, replace=False))


BUILTIN: dict[str, ObservationProtocol] = {p.name: p for p in (
    ObservationProtocol("subset", "ordered random subset of the path up to the goal (gr_libs, the paper's "
                        "baselines)", span="goal", random_subset=True),
    ObservationProtocol("prefix", "the first k pairs of the path up to the goal (the strict online variant)",
                        span="goal", random_subset=False),
    ObservationProtocol("horizon-subset", "ordered random subset of the padded fixed-horizon episode "
                        "(leaks the goal: steps after it sit on the goal cell)", span="horizon",
                        random_subset=True, leaks_goal=True),
    ObservationProtocol("horizon-prefix", "the first k pairs of the padded fixed-horizon episode "
                        "(leaks the goal at high observability)", span="horizon", random_subset=False,
                        leaks_goal=True),
)}


#: The protocol of a problem set's own observations (a symbolic problem set run as a task: each problem's
#: ``obs.dat`` scored against its ``real_hyp.dat``, :mod:`grail_bench.domains.symbolic.problem_set`).
DATASET = "dataset"


@dataclass(frozen=True)
class DatasetProtocol:
    """The ``dataset`` protocol: a task's own observations, as its domain gives them (a domain's optional
    ``dataset_observations(task)``), observed whole, at level 1, on the actions channel. It observes no
    demonstration, so :meth:`select` refuses."""

    name: str = DATASET
    description: str = ("a problem set's own observations (each problem's obs.dat against its real_hyp.dat), "
                        "whole, on the actions channel; symbolic problem sets run as tasks (--task PATH)")
    leaks_goal: bool = False

    def select(self, traj: Trajectory, fraction: float, rng: np.random.Generator,
               rounding: str = "ceil") -> np.ndarray:
        raise UserError(f"the {DATASET} protocol observes a problem set's own obs.dat, not a demonstration; it "
                        "applies to offline runs of a problem set (grail-bench run --task PATH)")


class UnknownProtocolError(UserError):
    """No protocol of that name is built in or registered."""


def _checked(protocol: object, target: str) -> ProtocolLike:
    if not isinstance(protocol, ProtocolLike):
        raise UserError(f"protocol entry point {target} lacks name, description, leaks_goal or select")
    return protocol


#: Every observation protocol: the built-in ones and those of the ``grail_bench.protocols`` entry points.
PROTOCOLS: Registry[ProtocolLike] = Registry("observation protocol", GROUP, check=_checked,
                                             unknown=UnknownProtocolError)
for _protocol in BUILTIN.values():
    PROTOCOLS.add(_protocol.name, _protocol)
PROTOCOLS.add(DATASET, DatasetProtocol())


def available_protocols() -> dict[str, str]:
    """Protocol names and what provides them (plugins are not imported)."""
    return PROTOCOLS.targets()


def canonical_name(name: str) -> str:
    """The registered name, mapping the deprecated ``random`` to ``subset`` (with a warning)."""
    if name in LEGACY_NAMES:
        warnings.warn(f"observation protocol {name!r} is deprecated; use {LEGACY_NAMES[name]!r}",
                      DeprecationWarning, stacklevel=3)
        return LEGACY_NAMES[name]
    return name


def get_protocol(name: str) -> ProtocolLike:
    """The protocol registered under ``name``.

    Raises:
        UnknownProtocolError: For names neither built in nor registered.
    """
    if isinstance(name, str):
        name = canonical_name(name)
    return PROTOCOLS.get(name)


def check_noise(noise: float) -> float:
    """A noise share, rounded to :data:`LEVEL_DECIMALS` decimals as it is stored."""
    try:
        value = float(noise)
    except (TypeError, ValueError):
        raise UserError(f"noise {noise!r} is not a number") from None
    if not 0.0 <= value <= 1.0 or math.isnan(value):
        raise UserError(f"noise {value:g} must be a share of the observed steps in [0, 1]")
    return round(value, LEVEL_DECIMALS)


def _check_channel(channel: str) -> None:
    if channel not in CHANNELS:
        raise UserError(f"unknown observation channel {channel!r}; choose one of {', '.join(CHANNELS)}")


class LabelParts(NamedTuple):
    """A stored protocol label, read: the protocol, its rounding, the noise share and the channel."""

    protocol: str
    rounding: str = "ceil"
    noise: float = 0.0
    channel: str = "pairs"


def protocol_label(name: str, rounding: str = "ceil", noise: float = 0.0, channel: str = "pairs") -> str:
    """What the store and records call an observation set-up: the protocol, then what differs from the default
    (``"subset"``, ``"subset+floor"``, ``"subset+noise0.2"``, ``"subset+floor+noise0.2+actions"``)."""
    _check_rounding(rounding)
    _check_channel(channel)
    noise = check_noise(noise)
    parts = [name] + ([rounding] if rounding != "ceil" else []) + ([f"noise{noise:g}"] if noise else [])
    return "+".join(parts + ([channel] if channel != "pairs" else []))


def parse_label(label: str) -> LabelParts:
    """``"subset+floor+noise0.2"`` -> ``LabelParts("subset", "floor", 0.2, "pairs")``; the inverse of
    :func:`protocol_label`.

    Raises:
        UserError: For a part that is no rounding, ``noise<share>`` or channel.
    """
    name, *rest = label.split("+")
    parts = LabelParts(name)
    for part in rest:
        if part in ROUNDINGS:
            parts = parts._replace(rounding=part)
        elif part in CHANNELS:
            parts = parts._replace(channel=part)
        elif part.startswith("noise"):
            parts = parts._replace(noise=check_noise(part.removeprefix("noise")))
        else:
            raise UserError(f"protocol label {label!r}: {part!r} is no rounding, noise<share> or channel")
    return parts


def n_spurious(noise: float, k: int) -> int:
    """How many of ``k`` observed steps are spurious at a ``noise`` share: the nearest whole number, halves up."""
    return min(k, math.floor(round(noise * k, 9) + 0.5))


@dataclass(frozen=True)
class SpuriousActions:
    """What a spurious action is drawn from (see the module docstring): the other actions of a ``Discrete``
    space, or a ``Box`` uniformly. Build it with :meth:`of`.

    Attributes:
        n: Discrete actions (0 for a box).
        start: The first discrete action.
        low, high: The box's bounds, flattened.
        shape: An action's shape.
    """

    n: int = 0
    start: int = 0
    low: tuple[float, ...] = ()
    high: tuple[float, ...] = ()
    shape: tuple[int, ...] = ()

    @classmethod
    def of(cls, space: Any) -> SpuriousActions:
        """The spurious actions of a gymnasium action space.

        Raises:
            UserError: For a space with no other action to draw (one action), an unbounded box, or any other
                kind of space.
        """
        from gymnasium import spaces

        if isinstance(space, spaces.Discrete):
            if space.n < 2:
                raise UserError(f"noisy observations replace an action by another one; {space} has only one")
            return cls(n=int(space.n), start=int(space.start))
        if isinstance(space, spaces.Box):
            if not space.is_bounded("both"):
                raise UserError(f"noisy observations draw actions uniformly in the box; {space} is unbounded")
            return cls(low=tuple(space.low.ravel().tolist()), high=tuple(space.high.ravel().tolist()),
                       shape=tuple(space.shape))
        raise UserError(f"noisy observations need a Discrete or Box action space, not {space}")

    @property
    def discrete(self) -> bool:
        return self.n > 0

    def others(self, action: int) -> list[int]:
        """The discrete actions a spurious step can show instead of ``action``."""
        return [a for a in range(self.start, self.start + self.n) if a != action]

    def density(self) -> float:
        """Probability (discrete) or density (box) of each action a spurious step can show."""
        if self.discrete:
            return 1.0 / (self.n - 1)
        return 1.0 / math.prod(h - lo for lo, h in zip(self.low, self.high))

    def draw(self, actions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Spurious replacements of ``actions`` (``(m, *shape)``), one each."""
        actions = np.asarray(actions)
        if self.discrete:
            offset = rng.integers(self.n - 1, size=len(actions))  # among the n - 1 others, uniformly
            shifted = self.start + offset
            return (shifted + (shifted >= actions)).astype(actions.dtype)
        low, high = np.reshape(self.low, self.shape), np.reshape(self.high, self.shape)
        return rng.uniform(low, high, size=(len(actions), *self.shape)).astype(actions.dtype)


def corrupt(observed: Trajectory, noise: float, spurious: SpuriousActions, rng: np.random.Generator) -> Trajectory:
    """``observed`` with :func:`n_spurious` of its steps, drawn uniformly, made spurious (states kept)."""
    k = len(observed.acts)
    m = n_spurious(noise, k)
    if m == 0:
        return observed
    steps = np.sort(rng.choice(k, size=m, replace=False))
    acts = np.array(observed.acts, copy=True)
    acts[steps] = spurious.draw(acts[steps], rng)
    return replace(observed, acts=acts)


def _blank(values: np.ndarray) -> np.ndarray:
    return np.full(np.shape(values), np.nan)


def project(observed: Trajectory, channel: str) -> Trajectory:
    """``observed`` as a channel shows it (see the module docstring): the hidden channel NaN."""
    _check_channel(channel)
    if channel == "pairs":
        return observed
    if channel == "actions":
        return replace(observed, obs=_blank(observed.obs))
    obs = np.asarray(observed.obs, dtype=float).copy()
    obs[-1] = np.nan
    return replace(observed, obs=obs, acts=_blank(observed.acts))


def observed_channel(observed: Any) -> str:
    """Which channel an observation carries: ``"states"`` (its actions NaN), ``"actions"`` (its states NaN)
    or ``"pairs"``."""
    def hidden(values: Any) -> bool:
        arr = np.asarray(values)
        return arr.dtype.kind == "f" and arr.size > 0 and bool(np.isnan(arr).all())

    if hidden(observed.acts):
        return "states"
    return "actions" if hidden(observed.obs) else "pairs"


@dataclass(frozen=True)
class ObservationProfile:
    """A named observation set-up of another toolkit: levels, rounding and protocols (one run each).

    Attributes:
        name: As ``--observation`` takes it.
        description: One line.
        levels: Observability levels.
        rounding: ``"ceil"`` or ``"floor"``.
        protocols: Built-in protocol names.
    """

    name: str
    description: str
    levels: tuple[float, ...]
    rounding: str
    protocols: tuple[str, ...]


#: Observation set-ups of other toolkits (see the module docstring).
PROFILES: dict[str, ObservationProfile] = {p.name: p for p in (
    ObservationProfile("gr_libs", "gr_libs' observations: 30/50/70/90/100 %, int(p * T) pairs, consecutive (prefix) "
                       "or not (an ordered random subset)", (0.3, 0.5, 0.7, 0.9, 1.0), "floor", ("prefix", "subset")),
)}


def get_profile(name: str) -> ObservationProfile:
    """The observation profile called ``name``.

    Raises:
        UserError: For an unknown name.
    """
    if name not in PROFILES:
        raise UserError(f"unknown observation profile {name!r}; choose one of {', '.join(PROFILES)}")
    return PROFILES[name]


#: For each built-in protocol, the one whose observation at level ``p`` is what an online observer has seen
#: at ``p``: the same span, revealed in time order.
PREFIX_OF = {"subset": "prefix", "prefix": "prefix", "horizon-subset": "horizon-prefix",
             "horizon-prefix": "horizon-prefix"}


@dataclass(frozen=True)
class ObservationSpec:
    """How a run observes test demonstrations: the protocol, its rounding, the levels and the observation model,
    resolved once.

    Build it with :meth:`resolve` when a run is planned; every later step
    (drawing observations, labelling rows, the ceilings) reads it and never
    resolves a protocol name again.

    Attributes:
        protocol: The registered protocol name (deprecated names already mapped).
        rounding: ``"ceil"`` or ``"floor"`` for the number of observed pairs.
        levels: Observability levels (empty for online runs, which observe every prefix).
        noise: Share of the observed steps made spurious (see the module docstring).
        channel: ``"pairs"``, ``"states"`` or ``"actions"``.
        spurious: What spurious actions are drawn from (needed when ``noise > 0``; not part of the label).
    """

    protocol: str
    rounding: str = "ceil"
    levels: tuple[float, ...] = ()
    noise: float = 0.0
    channel: str = "pairs"
    spurious: SpuriousActions | None = field(default=None, compare=False, repr=False)

    @classmethod
    def resolve(cls, protocol: str, rounding: str = "ceil", levels: Iterable[float] | str = (), *,
                noise: float = 0.0, channel: str = "pairs", action_space: Any = None) -> ObservationSpec:
        """Check a protocol name (mapping deprecated ones), a rounding, levels and the observation model.

        Args:
            action_space: The task's action space, where spurious actions are drawn (needed when ``noise > 0``).

        Raises:
            UserError: For an unknown protocol, rounding or channel, a level outside (0, 1], a noise share
                outside [0, 1], noise on the states channel (it hides the actions noise replaces), or noise
                without a Discrete or bounded Box action space.
        """
        _check_rounding(rounding)
        _check_channel(channel)
        noise = check_noise(noise)
        name = get_protocol(protocol).name
        if name == DATASET:  # a problem set's obs.dat holds actions only, as the dataset gives them
            if channel == "states" or noise:
                raise UserError(f"the {DATASET} protocol observes each obs.dat as the problem set gives it (its "
                                f"actions); drop {'--channel states' if channel == 'states' else '--noise'}")
            channel = "actions"
        parsed = parse_observability(levels) if (isinstance(levels, str) or list(levels)) else ()
        spurious = None
        if noise:
            if channel == "states":
                raise UserError("noise replaces observed actions, which the states channel hides; drop one")
            if action_space is None:
                raise UserError("noisy observations need the task's action space to draw spurious actions")
            spurious = SpuriousActions.of(action_space)
        return cls(name, rounding, parsed, noise, channel, spurious)

    @classmethod
    def from_label(cls, label: str, levels: Iterable[float] = (), action_space: Any = None) -> ObservationSpec:
        """The spec of a stored protocol label (``"subset+floor+noise0.2"``); observing with noise needs the
        ``action_space``."""
        parts = parse_label(label)
        spurious = SpuriousActions.of(action_space) if parts.noise and action_space is not None else None
        return cls(parts.protocol, parts.rounding, tuple(levels), parts.noise, parts.channel, spurious)

    @property
    def label(self) -> str:
        """What the store and records call it: ``"subset"``, ``"subset+floor"``, ``"subset+noise0.2"``, ..."""
        return protocol_label(self.protocol, self.rounding, self.noise, self.channel)

    @property
    def chosen(self) -> ProtocolLike:
        """The protocol object."""
        return get_protocol(self.protocol)

    def with_levels(self, levels: Iterable[float]) -> ObservationSpec:
        return replace(self, levels=tuple(levels))

    def rng(self, seed: int, level: float, purpose: str = "") -> np.random.Generator:
        """The random stream of one (seed, level) cell of this protocol, for one ``purpose`` of a mode.

        The channel draws nothing, so it does not key the stream: ``subset+states`` observes the very steps
        ``subset`` observes. Noise does (``subset+noise0.2`` has its own stream).
        """
        label = protocol_label(self.protocol, self.rounding, self.noise)
        return cell_rng(seed, level, f"{purpose}:{label}" if purpose else label)

    def observe(self, traj: Trajectory, level: float, rng: np.random.Generator | None) -> Trajectory:
        """:func:`observe` under this protocol and rounding, then the noise and the channel.

        Raises:
            UserError: For noise without :attr:`spurious`.
        """
        observed = observe(traj, level, self.chosen, rng, self.rounding)
        if self.noise:
            if self.spurious is None:
                raise UserError("noisy observations need the task's action space (ObservationSpec.resolve's "
                                "action_space)")
            if rng is None:
                raise ValueError("noisy observations draw at random and need an rng")
            observed = corrupt(observed, self.noise, self.spurious, rng)
        return project(observed, self.channel)


def observe(traj: Trajectory, fraction: float, protocol: str | ProtocolLike | None = None,
            rng: np.random.Generator | None = None, rounding: str | None = None, *,
            task: Any | None = None) -> Trajectory:
    """The part of a test demonstration a recognizer gets to see.

    Infos are dropped, so nothing about the goal leaks through them.

    Args:
        traj: A test demonstration.
        fraction: Observability level in (0, 1].
        protocol: A protocol or its name (see module docstring); default: ``task``'s own protocol (a
            :class:`~grail_bench.task.model.GRTask`'s ``protocol``), else ``prefix``.
        rng: Needed by random-subset protocols.
        rounding: ``"ceil"`` or ``"floor"`` for ``k``; default: ``task``'s, else ``ceil``.
        task: The task the demonstration is of, whose protocol and rounding are the defaults.

    Returns:
        A trajectory with ``k`` actions and ``k + 1`` states; ``acts[i]`` was
        taken in ``obs[i]`` (for subsets ``obs[k]`` follows the last pair).

    Raises:
        UserError: For a level outside (0, 1].
    """
    if isinstance(fraction, bool) or not isinstance(fraction, (int, float, np.integer, np.floating)) or not (
            0 < fraction <= 1):
        raise UserError(f"observability level must be a number in (0, 1], got {fraction!r}")
    if protocol is None:
        protocol = task.protocol if task is not None else "prefix"
    if rounding is None:
        rounding = task.rounding if task is not None else "ceil"
    chosen = get_protocol(protocol) if isinstance(protocol, str) else protocol
    if rng is None:
        if getattr(chosen, "random_subset", True):
            raise ValueError(f"observation protocol {chosen.name!r} draws at random and needs an rng")
        rng = np.random.default_rng(0)  # never drawn from
    idx = np.asarray(chosen.select(traj, fraction, rng, rounding), dtype=np.int64)
    if idx.ndim != 1 or len(idx) == 0 or np.any(np.diff(idx) <= 0) or idx[0] < 0 or idx[-1] >= len(traj.acts):
        raise UserError(f"protocol {chosen.name!r} selected invalid indices {idx.tolist()}")

    states = np.concatenate([traj.obs[idx], traj.obs[idx[-1] + 1][None]])
    return Trajectory(obs=states, acts=traj.acts[idx], infos=None, terminal=False)
