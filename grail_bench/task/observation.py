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
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Hashable, Iterable, Iterator, Protocol, Sequence, runtime_checkable

import numpy as np

from grail_bench.core.registry import Registry
from grail_bench.core.errors import UserError
from grail_bench.core.seeding import cell_rng
from grail_bench.core.trajectory import goal_horizon

if TYPE_CHECKING:  # imitation imports torch; task registration reads this module and must stay light
    from imitation.data.types import Trajectory

GROUP = "grail_bench.protocols"
ROUNDINGS = ("ceil", "floor")
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


def protocol_label(name: str, rounding: str = "ceil") -> str:
    """What the store and records call a protocol: ``"subset"``, or ``"subset+floor"`` when rounding down."""
    _check_rounding(rounding)
    return name if rounding == "ceil" else f"{name}+{rounding}"


def parse_label(label: str) -> tuple[str, str]:
    """``"subset+floor"`` -> ``("subset", "floor")``; the inverse of :func:`protocol_label`."""
    name, _, rounding = label.partition("+")
    return name, rounding or "ceil"


#: For each built-in protocol, the one whose observation at level ``p`` is what an online observer has seen
#: at ``p``: the same span, revealed in time order.
PREFIX_OF = {"subset": "prefix", "prefix": "prefix", "horizon-subset": "horizon-prefix",
             "horizon-prefix": "horizon-prefix"}


@dataclass(frozen=True)
class ObservationSpec:
    """How a run observes test demonstrations: the protocol, its rounding and the levels, resolved once.

    Build it with :meth:`resolve` when a run is planned; every later step
    (drawing observations, labelling rows, the ceilings) reads it and never
    resolves a protocol name again.

    Attributes:
        protocol: The registered protocol name (deprecated names already mapped).
        rounding: ``"ceil"`` or ``"floor"`` for the number of observed pairs.
        levels: Observability levels (empty for online runs, which observe every prefix).
    """

    protocol: str
    rounding: str = "ceil"
    levels: tuple[float, ...] = ()

    @classmethod
    def resolve(cls, protocol: str, rounding: str = "ceil", levels: Iterable[float] | str = ()) -> ObservationSpec:
        """Check a protocol name (mapping deprecated ones), a rounding and levels.

        Raises:
            UserError: For an unknown protocol or rounding, or a level outside (0, 1].
        """
        _check_rounding(rounding)
        name = get_protocol(protocol).name
        parsed = parse_observability(levels) if (isinstance(levels, str) or list(levels)) else ()
        return cls(name, rounding, parsed)

    @classmethod
    def from_label(cls, label: str, levels: Iterable[float] = ()) -> ObservationSpec:
        """The spec of a stored protocol label (``"subset+floor"``)."""
        name, rounding = parse_label(label)
        return cls(name, rounding, tuple(levels))

    @property
    def label(self) -> str:
        """What the store and records call it: ``"subset"``, or ``"subset+floor"`` when rounding down."""
        return protocol_label(self.protocol, self.rounding)

    @property
    def chosen(self) -> ProtocolLike:
        """The protocol object."""
        return get_protocol(self.protocol)

    def with_levels(self, levels: Iterable[float]) -> ObservationSpec:
        return ObservationSpec(self.protocol, self.rounding, tuple(levels))

    def rng(self, seed: int, level: float, purpose: str = "") -> np.random.Generator:
        """The random stream of one (seed, level) cell of this protocol, for one ``purpose`` of a mode."""
        return cell_rng(seed, level, f"{purpose}:{self.label}" if purpose else self.label)

    def observe(self, traj: Trajectory, level: float, rng: np.random.Generator | None) -> Trajectory:
        """:func:`observe` under this protocol and rounding."""
        return observe(traj, level, self.chosen, rng, self.rounding)


def observe(traj: Trajectory, fraction: float, protocol: str | ProtocolLike = "prefix",
            rng: np.random.Generator | None = None, rounding: str = "ceil") -> Trajectory:
    """The part of a test demonstration a recognizer gets to see.

    Infos are dropped, so nothing about the goal leaks through them.

    Args:
        traj: A test demonstration.
        fraction: Observability level in (0, 1].
        protocol: A protocol or its name (see module docstring).
        rng: Needed by random-subset protocols.
        rounding: ``"ceil"`` or ``"floor"`` for ``k``.

    Returns:
        A trajectory with ``k`` actions and ``k + 1`` states; ``acts[i]`` was
        taken in ``obs[i]`` (for subsets ``obs[k]`` follows the last pair).
    """
    chosen = get_protocol(protocol) if isinstance(protocol, str) else protocol
    if rng is None:
        if getattr(chosen, "random_subset", True):
            raise ValueError(f"observation protocol {chosen.name!r} draws at random and needs an rng")
        rng = np.random.default_rng(0)  # never drawn from
    idx = np.asarray(chosen.select(traj, fraction, rng, rounding), dtype=np.int64)
    if idx.ndim != 1 or len(idx) == 0 or np.any(np.diff(idx) <= 0) or idx[0] < 0 or idx[-1] >= len(traj.acts):
        raise UserError(f"protocol {chosen.name!r} selected invalid indices {idx.tolist()}")
    from imitation.data.types import Trajectory

    states = np.concatenate([traj.obs[idx], traj.obs[idx[-1] + 1][None]])
    return Trajectory(obs=states, acts=traj.acts[idx], infos=None, terminal=False)
