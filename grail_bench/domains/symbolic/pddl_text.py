"""PDDL text to plain lifted data: the STRIPS + typing subset (negative preconditions and equality included).

The ``pddl`` package (AI-Planning/pddl, MIT) parses; this module turns its
objects into :class:`LiftedDomain` and :class:`LiftedProblem`, plain tuples of
lower-case names that the grounder reads, and refuses anything outside the
subset in one line. Atoms are tuples ``(predicate, arg, ...)``; an atom's text
is ``(predicate arg ...)``, as in the dataset's ``hyps.dat`` and ``obs.dat``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from grail_bench.core.errors import UserError

Atom = tuple[str, ...]
#: A precondition literal: (positive, atom); an atom whose predicate is ``=`` is an equality.
Literal = tuple[bool, Atom]

# The dataset's domains use equality and negative preconditions without always declaring them (as classical
# planners accept); the parser insists on the declaration, so it is added where missing.
_IMPLIED = (":equality", ":negative-preconditions")


@dataclass(frozen=True)
class LiftedAction:
    """One action schema.

    Attributes:
        name: Lower-case action name.
        parameters: ``(variable, type)`` pairs, variables without ``?``.
        precondition: Conjunction of literals over variables and constants.
        add: Atoms the action makes true.
        delete: Atoms the action makes false.
    """

    name: str
    parameters: tuple[tuple[str, str], ...]
    precondition: tuple[Literal, ...]
    add: tuple[Atom, ...]
    delete: tuple[Atom, ...]


@dataclass(frozen=True)
class LiftedDomain:
    """A typed STRIPS domain.

    Attributes:
        name: Domain name.
        parents: Type -> its parent type (``object`` at the root).
        constants: Domain constants -> their type.
        predicates: Predicate name -> arity.
        actions: Action schemas, sorted by name.
    """

    name: str
    parents: dict[str, str]
    constants: dict[str, str]
    predicates: dict[str, int]
    actions: tuple[LiftedAction, ...]


@dataclass(frozen=True)
class LiftedProblem:
    """A problem's objects (constants of its domain included), initial state and goal.

    Attributes:
        name: Problem name.
        objects: Object -> its type.
        init: Atoms true initially (closed world).
        goal: Goal atoms (a conjunction).
    """

    name: str
    objects: dict[str, str]
    init: frozenset[Atom]
    goal: tuple[Atom, ...]


@lru_cache(maxsize=None)
def _parser(kind: str) -> Any:
    """One parser per kind, built once (building one compiles its grammar: about 0.3 s)."""
    if kind == "domain":
        from pddl.parser.domain import DomainParser

        return DomainParser()
    from pddl.parser.problem import ProblemParser

    return ProblemParser()


def _declare_implied(text: str) -> str:
    match = re.search(r"\(:requirements([^)]*)\)", text, flags=re.IGNORECASE)
    if match is None:
        return text
    declared = match.group(1).lower().split()
    missing = " ".join(r for r in _IMPLIED if r not in declared)
    return text[:match.end(1)] + (" " + missing if missing else "") + text[match.end(1):]


def _one_line(what: str, err: Exception) -> UserError:
    first = next((line.strip() for line in str(err).splitlines() if line.strip()), type(err).__name__)
    return UserError(f"{what}: {first}")


def _term(term: object) -> str:
    from pddl.logic.terms import Variable

    name = str(term.name).lower()  # type: ignore[attr-defined]
    return "?" + name if isinstance(term, Variable) else name


def _literals(formula: object, what: str) -> list[Literal]:
    """A precondition or goal as a conjunction of literals."""
    from pddl.logic.base import And, Not
    from pddl.logic.predicates import EqualTo, Predicate

    if formula is None:
        return []
    if isinstance(formula, And):
        return [lit for op in formula.operands for lit in _literals(op, what)]
    if isinstance(formula, Not):
        inner = _literals(formula.argument, what)
        if len(inner) != 1 or not inner[0][0]:
            raise UserError(f"{what}: only negated atoms are supported, got {formula}")
        return [(False, inner[0][1])]
    if isinstance(formula, Predicate):
        return [(True, (formula.name.lower(), *(_term(t) for t in formula.terms)))]
    if isinstance(formula, EqualTo):
        return [(True, ("=", _term(formula.left), _term(formula.right)))]
    raise UserError(f"{what}: {type(formula).__name__} is outside the STRIPS subset grail-bench grounds ({formula})")


def _typed(tags: frozenset[str], what: str) -> str:
    if len(tags) > 1:
        raise UserError(f"{what}: either-types are not supported ({sorted(tags)})")
    return next(iter(tags)).lower() if tags else "object"


def parse_domain(text: str) -> LiftedDomain:
    """Parse a domain's PDDL text.

    Raises:
        UserError: In one line, for text that does not parse or lies outside the STRIPS + typing subset
            (conditional or quantified effects, disjunctions, numeric fluents).
    """
    from pddl.logic.base import And, Not
    from pddl.logic.predicates import Predicate

    try:
        domain = _parser("domain")(_declare_implied(text.lower()))  # PDDL is case-insensitive
    except Exception as err:  # lark and pddl raise many kinds; all mean the text is not valid PDDL
        raise _one_line("domain.pddl does not parse", err) from None
    parents = {str(t).lower(): (str(p).lower() if p else "object") for t, p in domain.types.items()}
    actions = []
    for action in sorted(domain.actions, key=lambda a: a.name.lower()):
        what = f"domain.pddl: action {action.name}"
        params = tuple((v.name.lower(), _typed(v.type_tags, what)) for v in action.parameters)
        effects = action.effect.operands if isinstance(action.effect, And) else (
            () if action.effect is None else (action.effect,))
        add, delete = [], []
        for effect in effects:
            if isinstance(effect, Not) and isinstance(effect.argument, Predicate):
                delete.append((effect.argument.name.lower(), *(_term(t) for t in effect.argument.terms)))
            elif isinstance(effect, Predicate):
                add.append((effect.name.lower(), *(_term(t) for t in effect.terms)))
            else:
                raise UserError(f"{what}: effect {effect} is outside the STRIPS subset grail-bench grounds")
        actions.append(LiftedAction(action.name.lower(), params, tuple(_literals(action.precondition, what)),
                                    tuple(add), tuple(delete)))
    return LiftedDomain(
        name=str(domain.name).lower(),
        parents=parents,
        constants={c.name.lower(): _typed(c.type_tags, "domain.pddl: constants") for c in domain.constants},
        predicates={p.name.lower(): p.arity for p in domain.predicates},
        actions=tuple(actions),
    )


def parse_problem(text: str, domain: LiftedDomain) -> LiftedProblem:
    """Parse a problem's PDDL text (its goal a conjunction of atoms).

    Raises:
        UserError: In one line, for text that does not parse, an object of an undeclared type, or a goal
            that is not a conjunction of atoms.
    """
    try:
        problem = _parser("problem")(text.lower())
    except Exception as err:  # lark and pddl raise many kinds; all mean the text is not valid PDDL
        raise _one_line("the problem does not parse", err) from None
    objects = dict(domain.constants)
    for obj in problem.objects:
        kind = _typed(obj.type_tags, "problem objects")
        if kind != "object" and kind not in domain.parents:
            raise UserError(f"problem object {obj.name.lower()} has undeclared type {kind}")
        objects[obj.name.lower()] = kind
    init = []
    for fact in problem.init:
        lits = _literals(fact, "problem init")
        init += [atom for _, atom in lits]
    goal = _literals(problem.goal, "problem goal")
    if any(not positive for positive, _ in goal):
        raise UserError("problem goal: only conjunctions of atoms are supported")
    return LiftedProblem(str(problem.name).lower(), objects, frozenset(init), tuple(atom for _, atom in goal))


_ATOM = re.compile(r"\(\s*([^()\s]+)((?:\s+[^()\s]+)*)\s*\)")


def parse_atoms(line: str, what: str) -> tuple[Atom, ...]:
    """Atoms of one line such as ``(on a b), (clear a)`` (the dataset's commas optional), lower-cased.

    Raises:
        UserError: For text other than parenthesised atoms.
    """
    atoms = tuple(tuple(m.group(0)[1:-1].lower().split()) for m in _ATOM.finditer(line))
    rest = _ATOM.sub("", line).replace(",", "").strip()
    if rest or not atoms:
        raise UserError(f"{what}: expected atoms like (on a b), got {line.strip()!r}")
    return atoms


def atom_text(atom: Atom) -> str:
    """``("on", "a", "b") -> "(on a b)"``."""
    return "(" + " ".join(atom) + ")"
