"""Grounding a lifted problem into a :class:`~.strips.StripsModel`: only reachable, relevant operators.

1. Static predicates (in no action's effects) are evaluated while parameters are
   bound, with equality, so bindings that break them are never built.
2. A relaxed reachability pass (delete effects and negative preconditions
   ignored) keeps the operators that can ever apply.
3. A backward relevance pass keeps those that add or delete an atom some
   candidate goal needs, directly or through preconditions.

Atoms no kept operator changes become static facts (true) or disappear
(never true); the rest are the fluents, sorted, and the operators are sorted by
name, so the model is the same for the same text.

Grounding is bounded: at most :data:`BINDING_LIMIT` parameter bindings are tried
and :data:`OPERATOR_LIMIT` ground operators built (a 30x30 grid tries 4,380 and
builds 3,480); a larger problem is refused in one line before it fills memory.
"""

from __future__ import annotations

from typing import Iterable, Iterator

from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.pddl_text import Atom, LiftedAction, LiftedDomain, LiftedProblem, Literal, atom_text
from grail_bench.domains.symbolic.strips import Operator, StripsModel

BINDING_LIMIT = 20_000_000  #: parameter bindings grounding tries at most, over every action
OPERATOR_LIMIT = 500_000  #: ground operators (before pruning) grounding builds at most


def _too_large(what: str, limit: int) -> UserError:
    return UserError(f"the problem is too large to ground: more than {limit:,} {what} (grail-bench's grounder "
                     "enumerates bindings; split the problem or use fewer objects)")


def _objects_by_type(domain: LiftedDomain, objects: dict[str, str]) -> dict[str, list[str]]:
    """Type -> the objects of that type or a subtype, sorted."""
    out: dict[str, list[str]] = {}
    for obj, kind in sorted(objects.items()):
        seen = set()
        while kind not in seen:
            seen.add(kind)
            out.setdefault(kind, []).append(obj)
            if kind == "object":
                break
            kind = domain.parents.get(kind, "object")
    return out


def _bind(atom: Atom, binding: dict[str, str]) -> Atom:
    return (atom[0], *(binding.get(t, t) for t in atom[1:]))


def _bindings(action: LiftedAction, by_type: dict[str, list[str]], static_preds: set[str],
              static_init: frozenset[Atom], tried: list[int]) -> Iterator[dict[str, str]]:
    """Parameter bindings that satisfy the action's static and equality literals, checked as soon as bound.

    ``tried[0]`` counts the bindings tried, across calls.

    Raises:
        UserError: Past :data:`BINDING_LIMIT` bindings tried.
    """
    names = ["?" + v for v, _ in action.parameters]
    checks: list[list[Literal]] = [[] for _ in names]  # literal checked once parameter i is bound
    for positive, atom in action.precondition:
        if atom[0] != "=" and atom[0] not in static_preds:
            continue
        last = max((names.index(t) for t in atom[1:] if t in names), default=-1)
        if last < 0:
            checks_now = [(positive, atom)]
            if not _holds(checks_now, {}, static_init):
                return
            continue
        checks[last].append((positive, atom))

    # positive static literals whose last-bound parameter appears once: they pick that parameter's objects out
    # of an index of the static facts (a grid's move binds ?to among ?from's neighbours, not among every cell)
    filters = [[(atom, atom.index(names[i])) for positive, atom in checks[i]
                if positive and atom[0] != "=" and atom[1:].count(names[i]) == 1] for i in range(len(names))]
    slots = {(atom[0], pos): _slot(static_init, atom[0], pos) for kept in filters for atom, pos in kept}
    binding: dict[str, str] = {}

    def candidates(i: int) -> list[str]:
        objects = by_type.get(action.parameters[i][1], [])
        for atom, pos in filters[i]:
            bound = _bind(atom, binding)
            allowed = slots[atom[0], pos].get(bound[1:pos] + bound[pos + 1:], set())
            objects = [obj for obj in objects if obj in allowed]
        return objects

    def extend(i: int) -> Iterator[dict[str, str]]:
        if i == len(names):
            yield dict(binding)
            return
        for obj in candidates(i):
            tried[0] += 1
            if tried[0] > BINDING_LIMIT:
                raise _too_large("parameter bindings", BINDING_LIMIT)
            binding[names[i]] = obj
            if _holds(checks[i], binding, static_init):
                yield from extend(i + 1)
        binding.pop(names[i], None)

    yield from extend(0)


def _slot(static_init: frozenset[Atom], predicate: str, pos: int) -> dict[tuple[str, ...], set[str]]:
    """The static facts of ``predicate`` by their other arguments: the objects found at position ``pos``."""
    out: dict[tuple[str, ...], set[str]] = {}
    for fact in static_init:
        if fact[0] == predicate and len(fact) > pos:
            out.setdefault(fact[1:pos] + fact[pos + 1:], set()).add(fact[pos])
    return out


def _holds(literals: Iterable[Literal], binding: dict[str, str], static_init: frozenset[Atom]) -> bool:
    for positive, atom in literals:
        ground = _bind(atom, binding)
        value = ground[1] == ground[2] if ground[0] == "=" else ground in static_init
        if value != positive:
            return False
    return True


def ground(domain: LiftedDomain, problem: LiftedProblem, goals: Iterable[Iterable[Atom]]) -> StripsModel:
    """The grounded model of ``problem``, pruned to what the candidate ``goals`` can need.

    Raises:
        UserError: For an init or goal atom naming an unknown predicate or object, or a problem past the
            grounding limits.
    """
    goals = [tuple(g) for g in goals]
    for what, atoms in (("init", problem.init), *((f"goal {i}", g) for i, g in enumerate(goals))):
        for atom in atoms:
            if atom[0] not in domain.predicates:
                raise UserError(f"{what}: {atom_text(atom)} names unknown predicate {atom[0]!r}")
            unknown = [a for a in atom[1:] if a not in problem.objects]
            if unknown:
                raise UserError(f"{what}: {atom_text(atom)} names unknown object {unknown[0]!r}")
    changing = {atom[0] for a in domain.actions for atom in (*a.add, *a.delete)}
    static_preds = set(domain.predicates) - changing
    static_init = frozenset(a for a in problem.init if a[0] in static_preds)
    by_type = _objects_by_type(domain, problem.objects)

    candidates: list[tuple[Atom, list[Atom], list[Atom], list[Atom], list[Atom]]] = []
    tried = [0]
    for action in domain.actions:
        dynamic = [(p, atom) for p, atom in action.precondition if atom[0] != "=" and atom[0] not in static_preds]
        for binding in _bindings(action, by_type, static_preds, static_init, tried):
            if len(candidates) >= OPERATOR_LIMIT:
                raise _too_large("ground operators", OPERATOR_LIMIT)
            name = (action.name, *(binding["?" + v] for v, _ in action.parameters))
            pre = [_bind(a, binding) for p, a in dynamic if p]
            neg = [_bind(a, binding) for p, a in dynamic if not p]
            add = [_bind(a, binding) for a in action.add]
            delete = [_bind(a, binding) for a in action.delete]
            candidates.append((name, pre, neg, add, delete))

    init_dynamic = frozenset(a for a in problem.init if a[0] not in static_preds)
    reached, reachable, changed = set(init_dynamic), [False] * len(candidates), True
    while changed:  # relaxed reachability
        changed = False
        for i, (_, pre, _, add, _) in enumerate(candidates):
            if not reachable[i] and all(a in reached for a in pre):
                reachable[i], changed = True, True
                reached.update(add)
    kept = [c for c, ok in zip(candidates, reachable) if ok]

    relevant, useful, changed = {a for g in goals for a in g}, [False] * len(kept), True
    while changed:  # backward relevance
        changed = False
        for i, (_, pre, neg, add, delete) in enumerate(kept):
            if not useful[i] and any(a in relevant for a in (*add, *delete)):
                useful[i], changed = True, True
                relevant.update(pre)
                relevant.update(neg)
    kept = [c for c, ok in zip(kept, useful) if ok]

    touched = {a for _, _, _, add, delete in kept for a in (*add, *delete)}
    fluents = tuple(sorted(a for a in touched if a in reached))
    index = {f: i for i, f in enumerate(fluents)}
    static = static_init | {a for a in init_dynamic if a not in touched}
    operators = []
    for name, pre, neg, add, delete in sorted(kept, key=lambda c: c[0]):
        if any(a not in index and a not in static for a in pre):
            continue  # needs an atom that never holds
        if any(a in static for a in neg):
            continue  # forbids an atom that always holds
        operators.append(Operator(
            name=name,
            pre=tuple(sorted(index[a] for a in set(pre) if a in index)),
            pre_neg=tuple(sorted(index[a] for a in set(neg) if a in index)),
            add=tuple(sorted(index[a] for a in set(add) if a in index)),
            delete=tuple(sorted(index[a] for a in set(delete) - set(add) if a in index)),
        ))
    init = 0
    for atom in init_dynamic:
        if atom in index:
            init |= 1 << (len(fluents) - 1 - index[atom])
    return StripsModel(fluents=fluents, operators=tuple(operators), init=init, static=static)
