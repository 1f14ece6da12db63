"""``landmarks``: landmark-based goal recognition (Pereira, Oren & Meneguzzi, AAAI 2017).

"Landmark-based heuristics for goal recognition" scores a candidate goal by how many of its landmarks
(facts every plan for it must make true at some point) the observed actions show achieved.

Landmarks, per goal fact. The fact landmarks of each fact ``g`` of a goal are extracted from the initial
state by Hoffmann, Porteous & Sebastia's (JAIR 2004) backchaining on the relaxed planning graph, as the
paper does: starting from ``g``, a landmark ``l`` not true initially has as candidate landmarks the
preconditions shared by all its *first achievers* (the operators adding ``l`` that are applicable in the
relaxed planning graph's layer before the one ``l`` first appears in); a candidate ``p`` is kept when it is
true initially or verified (``g`` is unreachable in the delete relaxation without the operators adding
``p``), ordered before ``l``, and backchained from in turn. Only fact landmarks are kept (HPS04's
disjunctive ones are not, as in the paper). ``L_g`` is ``g`` and every landmark found from it; a goal's
landmarks ``L_G`` are the union over its facts ``g ∈ G``.

Achieved landmarks (the paper's ComputeAchievedLandmarks): the landmarks true in the initial state, those
among the preconditions and add effects of the observed actions, and every landmark ordered before an
achieved one (it must have been achieved earlier, even if its achiever went unobserved). ``AL_g`` and
``AL_G`` are the achieved members of ``L_g`` and ``L_G``.

Heuristics (:attr:`LandmarksConfig.heuristic`), each the score, higher = more likely:

* ``"completion"``, goal completion (the paper's main one): ``h_gc(G) = (1 / |G|) Σ_{g ∈ G} |AL_g| / |L_g|``,
  the mean over the goal's facts of the share of their landmarks achieved;
* ``"uniqueness"``, landmark uniqueness: with ``U(l) = 1 / |{G' ∈ 𝒢 : l ∈ L_G'}|`` (the inverse of the number
  of candidate goals having ``l`` as landmark), ``h_uniq(G) = Σ_{l ∈ AL_G} U(l) / Σ_{l ∈ L_G} U(l)``.

Scores lie in [0, 1] and are the heuristic values as the paper ranks them (its threshold ``θ``, which
returns every goal within ``θ`` of the best, is the harness's business: it ranks the scores). It reads the
observed actions only (``channels = {"pairs", "actions"}``), learns nothing from demonstrations (``fit``
reads the grounded model and the goals from the task's envs) and refuses a task of another domain where the
run is planned (``check_task``). Nothing is learnt per goal, so ``set_goals`` takes any of the task's
hypotheses, fitted or not (zero-shot goals).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Literal, Mapping, Sequence

from grail_bench.contrib.strips_base import StripsRecognizer
from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Goal
from grail_bench.domains.symbolic.strips import StripsModel

HEURISTICS = ("completion", "uniqueness")


@dataclass(frozen=True)
class LandmarksConfig:
    """Landmark-based recognition's settings.

    Attributes:
        heuristic: ``"completion"`` (goal completion ``h_gc``, the paper's main one) or ``"uniqueness"``
            (landmark uniqueness ``h_uniq``).
    """

    heuristic: Literal["completion", "uniqueness"] = "completion"

    def __post_init__(self) -> None:
        if self.heuristic not in HEURISTICS:
            raise UserError(f"unknown heuristic {self.heuristic!r}; choose one of {', '.join(HEURISTICS)}")


@dataclass(frozen=True)
class LandmarkGraph:
    """The fact landmarks of one fact, with their orderings.

    Attributes:
        target: The fact (fluent index).
        landmarks: Its fact landmarks, itself included.
        before: Landmark -> the landmarks found ordered directly before it.
    """

    target: int
    landmarks: frozenset[int]
    before: Mapping[int, frozenset[int]]

    def closure(self, facts: set[int]) -> set[int]:
        """The landmarks among ``facts`` and every landmark ordered (transitively) before one of them."""
        out = {l for l in self.landmarks if l in facts}
        stack = list(out)
        while stack:
            for p in self.before.get(stack.pop(), ()):
                if p not in out:
                    out.add(p)
                    stack.append(p)
        return out


def facts(model: StripsModel, state: int) -> set[int]:
    """The fluent indices a state (or goal mask) holds."""
    return {i for i in range(model.n_fluents) if state & model.bit(i)}


def relaxed_layers(model: StripsModel) -> tuple[dict[int, int], dict[int, int]]:
    """The relaxed planning graph from the initial state: ``(fact -> first layer, operator -> first layer)``;
    unreachable facts and operators are absent."""
    level = {f: 0 for f in facts(model, model.init)}
    op_level: dict[int, int] = {}
    layer = 0
    while True:
        new: set[int] = set()
        for i, op in enumerate(model.operators):
            if i not in op_level and all(p in level for p in op.pre):
                op_level[i] = layer
                new.update(f for f in op.add if f not in level)
        if not new:
            return level, op_level
        layer += 1
        level.update((f, layer) for f in new)


def _relaxed_reachable(model: StripsModel, target: int, banned: int) -> bool:
    """Whether fact ``target`` is reachable in the delete relaxation without the operators adding ``banned``."""
    bit, goal = model.bit(banned), model.bit(target)
    ops = [(pre, add) for pre, add in model.relaxed_masks() if not add & bit]
    reached = model.init
    while not reached & goal:
        grown = reached
        for pre, add in ops:
            if reached & pre == pre:
                grown |= add
        if grown == reached:
            return False
        reached = grown
    return True


def fact_landmarks(model: StripsModel, target: int,
                   layers: tuple[dict[int, int], dict[int, int]] | None = None) -> LandmarkGraph:
    """The fact landmarks of fact ``target`` from the initial state (Hoffmann et al.'s backchaining with
    verification; see the module docstring).

    Args:
        model: The grounded model.
        target: The fact (fluent index).
        layers: :func:`relaxed_layers` of the model, when already computed.
    """
    level, op_level = layers or relaxed_layers(model)
    init = facts(model, model.init)
    landmarks, before = {target}, {target: set()}
    queue = deque([target])
    while queue:
        l = queue.popleft()
        if l in init or l not in level:
            continue
        first = [model.operators[i].pre for i, at in op_level.items()
                 if at <= level[l] - 1 and l in model.operators[i].add]
        shared = set.intersection(*(set(pre) for pre in first))
        for p in sorted(shared):
            if p not in landmarks:
                if p not in init and _relaxed_reachable(model, target, p):
                    continue
                landmarks.add(p)
                before[p] = set()
                queue.append(p)
            before[l].add(p)
    return LandmarkGraph(target=target, landmarks=frozenset(landmarks),
                         before={l: frozenset(ps) for l, ps in before.items()})


def observed_facts(model: StripsModel, observed: Sequence[int]) -> set[int]:
    """The facts the initial state and the observed actions show achieved: the initial state's, and the
    preconditions and add effects of every observed action."""
    out = facts(model, model.init)
    for op in observed:
        out.update(model.operators[op].pre)
        out.update(model.operators[op].add)
    return out


def goal_completion(graphs: Sequence[LandmarkGraph], achieved: set[int]) -> float:
    """``h_gc``: the mean over a goal's facts of the share of their landmarks achieved."""
    return sum(len(g.closure(achieved)) / len(g.landmarks) for g in graphs) / len(graphs)


def uniqueness(graphs: Sequence[LandmarkGraph], achieved: set[int], weight: Mapping[int, float]) -> float:
    """``h_uniq``: the uniqueness-weighted share of a goal's landmarks achieved (``weight``: ``U(l)``)."""
    landmarks = set().union(*(g.landmarks for g in graphs))
    done = set().union(*(g.closure(achieved) for g in graphs))
    return sum(weight[l] for l in done) / sum(weight[l] for l in landmarks)


class LandmarkRecognizer(StripsRecognizer):
    """Landmark-based goal recognition: each goal scored by the share of its landmarks the observations achieve.

    Settings: :class:`LandmarksConfig`. ``fit`` needs no demonstrations (it reads the model from
    ``env_factory``) and extracts every goal's landmarks; see the module docstring for the heuristics.
    """

    name = "landmarks"
    paper_name = "Landmarks (Pereira et al. 2017)"
    Config = LandmarksConfig
    config: LandmarksConfig

    def fitted(self) -> None:
        layers = relaxed_layers(self.model)
        graphs: dict[int, LandmarkGraph] = {}
        self.graphs: list[list[LandmarkGraph]] = []
        for mask in self.goal_masks:
            goal_facts = sorted(facts(self.model, mask))
            for f in goal_facts:
                if f not in graphs:
                    graphs[f] = fact_landmarks(self.model, f, layers)
            self.graphs.append([graphs[f] for f in goal_facts])
        holders: dict[int, int] = {}
        for goal_graphs in self.graphs:
            for l in set().union(*(g.landmarks for g in goal_graphs)):
                holders[l] = holders.get(l, 0) + 1
        self.weight = {l: 1.0 / n for l, n in holders.items()}

    def score(self, observed: Any) -> Mapping[Goal, float]:
        """The chosen heuristic's value per goal, from the observed actions.

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For a malformed observation.
        """
        achieved = observed_facts(self.model, self.observed_operators(observed))
        if self.config.heuristic == "completion":
            return {goal: goal_completion(g, achieved) for goal, g in zip(self.goals, self.graphs)}
        return {goal: uniqueness(g, achieved, self.weight) for goal, g in zip(self.goals, self.graphs)}
