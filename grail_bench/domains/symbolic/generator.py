"""The built-in goal-recognition problems: blocks-world, grid navigation and logistics.

Small problems (3-4 candidate goals, optimal plans of 5-12 actions, at most
16 fluents so that tables over every state fit) whose PDDL is grail-bench's
own text. :func:`builtin_problem` builds one in memory (nothing is read from
disk or downloaded); :func:`write_dataset` writes them in the dataset's layout,
one archive per true goal and observability level, ``obs.dat`` an ordered
random subset of an optimal plan, as the dataset's archives are.

* ``blocks``: three blocks, ``a`` on ``b``, ``c`` on the table; four towers
  of all three blocks (6 actions each).
* ``grid``: a 5x3 grid of cells with one blocked cell at (2, 1); the robot
  starts at (0, 1); three cells on the far side (5, 5 and 6 actions).
* ``logistics``: two cities (an airport and one or two other places each), a
  truck per city, an airplane and one package; four goals of 5-12 actions.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.pddl_text import Atom, atom_text
from grail_bench.domains.symbolic.problem import PLACEHOLDER, GRProblem

BLOCKS_DOMAIN = """\
; Blocks-world: a one-handed robot stacks blocks (grail-bench's text).
(define (domain blocks)
  (:requirements :strips :typing :equality)
  (:types block)
  (:predicates (on ?top ?below - block) (ontable ?b - block) (clear ?b - block)
               (holding ?b - block) (handempty))
  (:action pick-up
    :parameters (?b - block)
    :precondition (and (handempty) (clear ?b) (ontable ?b))
    :effect (and (holding ?b) (not (handempty)) (not (clear ?b)) (not (ontable ?b))))
  (:action put-down
    :parameters (?b - block)
    :precondition (holding ?b)
    :effect (and (handempty) (clear ?b) (ontable ?b) (not (holding ?b))))
  (:action stack
    :parameters (?top ?below - block)
    :precondition (and (holding ?top) (clear ?below) (not (= ?top ?below)))
    :effect (and (on ?top ?below) (clear ?top) (handempty) (not (holding ?top)) (not (clear ?below))))
  (:action unstack
    :parameters (?top ?below - block)
    :precondition (and (handempty) (clear ?top) (on ?top ?below) (not (= ?top ?below)))
    :effect (and (holding ?top) (clear ?below) (not (handempty)) (not (clear ?top)) (not (on ?top ?below)))))
"""

GRID_DOMAIN = """\
; Grid navigation: a robot moves between adjacent free cells (grail-bench's text).
(define (domain grid-navigation)
  (:requirements :strips :typing)
  (:types cell)
  (:predicates (robot-at ?c - cell) (adjacent ?from ?to - cell))
  (:action move
    :parameters (?from ?to - cell)
    :precondition (and (robot-at ?from) (adjacent ?from ?to))
    :effect (and (robot-at ?to) (not (robot-at ?from)))))
"""

LOGISTICS_DOMAIN = """\
; Logistics: trucks drive within a city, airplanes fly between airports, both carry packages
; (grail-bench's text).
(define (domain logistics)
  (:requirements :strips :typing :equality)
  (:types truck airplane - vehicle
          package vehicle - thing
          airport location - place
          city)
  (:predicates (in-city ?p - place ?c - city) (at ?x - thing ?p - place) (in ?pkg - package ?v - vehicle))
  (:action load-truck
    :parameters (?pkg - package ?t - truck ?p - place)
    :precondition (and (at ?t ?p) (at ?pkg ?p))
    :effect (and (in ?pkg ?t) (not (at ?pkg ?p))))
  (:action unload-truck
    :parameters (?pkg - package ?t - truck ?p - place)
    :precondition (and (at ?t ?p) (in ?pkg ?t))
    :effect (and (at ?pkg ?p) (not (in ?pkg ?t))))
  (:action load-airplane
    :parameters (?pkg - package ?a - airplane ?p - airport)
    :precondition (and (at ?a ?p) (at ?pkg ?p))
    :effect (and (in ?pkg ?a) (not (at ?pkg ?p))))
  (:action unload-airplane
    :parameters (?pkg - package ?a - airplane ?p - airport)
    :precondition (and (at ?a ?p) (in ?pkg ?a))
    :effect (and (at ?pkg ?p) (not (in ?pkg ?a))))
  (:action drive-truck
    :parameters (?t - truck ?from ?to - place ?c - city)
    :precondition (and (at ?t ?from) (in-city ?from ?c) (in-city ?to ?c) (not (= ?from ?to)))
    :effect (and (at ?t ?to) (not (at ?t ?from))))
  (:action fly-airplane
    :parameters (?a - airplane ?from ?to - airport)
    :precondition (and (at ?a ?from) (not (= ?from ?to)))
    :effect (and (at ?a ?to) (not (at ?a ?from)))))
"""


def _template(name: str, domain: str, objects: str, init: Sequence[Atom]) -> str:
    facts = "\n    ".join(atom_text(a) for a in init)
    return (f"(define (problem {name})\n  (:domain {domain})\n  (:objects {objects})\n"
            f"  (:init\n    {facts})\n  (:goal (and\n    {PLACEHOLDER}\n  )))\n")


def _blocks() -> GRProblem:
    init = [("handempty",), ("on", "a", "b"), ("ontable", "b"), ("ontable", "c"), ("clear", "a"), ("clear", "c")]
    towers = [("c", "b", "a"), ("a", "b", "c"), ("b", "c", "a"), ("a", "c", "b")]  # top to bottom
    hyps = tuple(((("on", t[0], t[1]), ("on", t[1], t[2]))) for t in towers)
    return GRProblem("blocks", BLOCKS_DOMAIN, _template("blocks-3", "blocks", "a b c - block", init),
                     hyps, hyps[0], ())


def _cell(x: int, y: int) -> str:
    return f"x{x}y{y}"


def _grid() -> GRProblem:
    width, height, blocked = 5, 3, {(2, 1)}
    free = [(x, y) for y in range(height) for x in range(width) if (x, y) not in blocked]
    init: list[Atom] = [("robot-at", _cell(0, 1))]
    for x, y in free:
        for nx, ny in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if (nx, ny) in free:
                init.append(("adjacent", _cell(x, y), _cell(nx, ny)))
    objects = " ".join(_cell(x, y) for x, y in free) + " - cell"
    hyps = tuple(((("robot-at", _cell(x, y)),)) for x, y in ((4, 0), (4, 2), (4, 1)))
    return GRProblem("grid", GRID_DOMAIN, _template("grid-5x3", "grid-navigation", objects, init), hyps, hyps[0], ())


def _logistics() -> GRProblem:
    objects = ("t1 t2 - truck p1 - airplane pkg - package apt1 apt2 - airport l11 l12 l21 - location "
               "c1 c2 - city")
    init: list[Atom] = [
        ("in-city", "apt1", "c1"), ("in-city", "l11", "c1"), ("in-city", "l12", "c1"),
        ("in-city", "apt2", "c2"), ("in-city", "l21", "c2"),
        ("at", "t1", "l12"), ("at", "t2", "l21"), ("at", "p1", "apt2"), ("at", "pkg", "l11"),
    ]
    hyps: tuple[tuple[Atom, ...], ...] = (
        (("at", "pkg", "apt2"),),
        (("at", "pkg", "l21"),),
        (("at", "pkg", "l12"), ("at", "p1", "apt1")),
        (("at", "pkg", "apt1"), ("at", "t2", "apt2")),
    )
    return GRProblem("logistics", LOGISTICS_DOMAIN, _template("logistics-2-cities", "logistics", objects, init),
                     hyps, hyps[0], ())


BUILDERS: dict[str, Callable[[], GRProblem]] = {"blocks": _blocks, "grid": _grid, "logistics": _logistics}
#: Names of the built-in problems (an env's ``problem`` parameter).
BUILTIN = tuple(BUILDERS)
#: Candidate goals per built-in problem (checked by the domain without building anything).
N_GOALS = {"blocks": 4, "grid": 3, "logistics": 4}
#: The dataset's observability levels, in percent.
LEVELS = (10, 30, 50, 70, 100)


def builtin_problem(name: str) -> GRProblem:
    """A built-in problem, its true goal the first hypothesis and no observations.

    Raises:
        UserError: For an unknown name.
    """
    if name not in BUILDERS:
        raise UserError(f"unknown built-in problem {name!r}; choose one of {', '.join(BUILTIN)} or give a path")
    return BUILDERS[name]()


def observed(problem: GRProblem, goal: int, level: int, rng: np.random.Generator) -> GRProblem:
    """``problem`` with true goal ``goal`` and, as ``obs.dat``, an ordered random subset of ``level`` percent
    (rounded up, at least one) of an optimal plan drawn uniformly."""
    from dataclasses import replace

    from grail_bench.domains.symbolic.planner import optimal_plan_graph

    model = problem.model
    plan = optimal_plan_graph(model, problem.goal_masks[goal]).sample(rng)
    k = max(1, -(-level * len(plan) // 100))
    keep = np.sort(rng.choice(len(plan), size=min(k, len(plan)), replace=False))
    return replace(problem, real_hyp=problem.hypotheses[goal],
                   observations=tuple(model.operators[plan[i]].name for i in keep))


def write_dataset(folder: str | Path, names: Sequence[str] = BUILTIN, levels: Sequence[int] = LEVELS,
                  seed: int = 0) -> list[Path]:
    """Write the built-in problems in the dataset's layout: ``<name>/<level>/<name>_hyp-<goal>_<level>.tar.bz2``
    for every candidate goal and level; returns the archives written."""
    from grail_bench.domains.symbolic.dataset import write_problem

    rng = np.random.default_rng(seed)
    out = []
    for name in names:
        problem = builtin_problem(name)
        for level in levels:
            for goal in range(len(problem.hypotheses)):
                path = Path(folder) / name / str(level) / f"{name}_hyp-{goal}_{level}.tar.bz2"
                out.append(write_problem(observed(problem, goal, level, rng), path))
    return out
