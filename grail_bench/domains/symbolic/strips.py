"""The grounded STRIPS model: fluents in a fixed order, operators with pre/add/del index sets.

A state is a Python ``int`` whose bits are the true fluents, fluent ``i`` at bit
``n_fluents - 1 - i``: so the state's integer equals
:func:`grail_bench.core.spaces.state_index` of its observation (the binary
vector :meth:`StripsModel.vector`) in the env's ``MultiDiscrete([2] * n_fluents)``
space, and tables over state indices are tables over states.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Iterable, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.pddl_text import Atom, atom_text

#: Largest number of states (2 ** n_fluents) tables over every state are built for.
MAX_TABLE_STATES = 1 << 16


@dataclass(frozen=True)
class Operator:
    """One ground operator.

    Attributes:
        name: Its atom, e.g. ``("stack", "a", "b")`` (text: :attr:`text`).
        pre: Fluent indices that must hold.
        pre_neg: Fluent indices that must not hold (negative preconditions).
        add: Fluent indices it makes true.
        delete: Fluent indices it makes false (a fluent both added and deleted ends true).
    """

    name: Atom
    pre: tuple[int, ...]
    pre_neg: tuple[int, ...]
    add: tuple[int, ...]
    delete: tuple[int, ...]

    @property
    def text(self) -> str:
        """``(stack a b)``, as in the dataset's ``obs.dat``."""
        return atom_text(self.name)


@dataclass(frozen=True)
class StripsModel:
    """A grounded problem without its goal (the candidate goals share it).

    Attributes:
        fluents: Ground atoms that can change, in state-bit order.
        operators: Ground operators, in action-index order (sorted by name).
        init: The initial state.
        static: Atoms true in every state (static facts, left out of :attr:`fluents`).
    """

    fluents: tuple[Atom, ...]
    operators: tuple[Operator, ...]
    init: int
    static: frozenset[Atom]
    _fluent_index: dict[Atom, int] = field(init=False, repr=False, compare=False)
    _op_index: dict[Atom, int] = field(init=False, repr=False, compare=False)
    _masks: tuple[tuple[int, int, int, int], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_fluent_index", {f: i for i, f in enumerate(self.fluents)})
        object.__setattr__(self, "_op_index", {op.name: i for i, op in enumerate(self.operators)})
        object.__setattr__(self, "_masks", tuple(
            (self.mask(op.pre), self.mask(op.pre_neg), self.mask(op.add), self.mask(op.delete))
            for op in self.operators))

    @property
    def n_fluents(self) -> int:
        return len(self.fluents)

    @property
    def n_operators(self) -> int:
        return len(self.operators)

    def bit(self, fluent: int) -> int:
        """The state bit of fluent ``fluent``."""
        return 1 << (len(self.fluents) - 1 - fluent)

    def mask(self, fluents: Iterable[int]) -> int:
        """The state holding exactly ``fluents``."""
        out = 0
        for f in fluents:
            out |= self.bit(f)
        return out

    def fluent_index(self, atom: Atom) -> int:
        """Index of a fluent atom; raises KeyError for atoms that are no fluent (static or unreachable)."""
        return self._fluent_index[atom]

    def operator_index(self, name: Atom | str) -> int:
        """Action index of a ground operator, by atom or text such as ``"(stack a b)"``.

        Raises:
            UserError: For an operator the grounded model does not have (unknown, or never applicable).
        """
        key = tuple(name.strip()[1:-1].lower().split()) if isinstance(name, str) else name
        try:
            return self._op_index[key]
        except KeyError:
            raise UserError(f"{atom_text(key)} is no reachable ground operator of this problem") from None

    def atoms(self, state: int) -> frozenset[Atom]:
        """The fluents true in ``state``."""
        return frozenset(f for i, f in enumerate(self.fluents) if state & self.bit(i))

    def applicable(self, state: int, op: int) -> bool:
        pre, neg, _, _ = self._masks[op]
        return state & pre == pre and not state & neg

    def apply(self, state: int, op: int) -> int:
        """The successor of ``state`` under ``op`` (assumed applicable)."""
        _, _, add, delete = self._masks[op]
        return (state & ~delete) | add

    def step(self, state: int, op: int) -> int:
        """The successor, or ``state`` itself when ``op`` is not applicable there (the env's rule)."""
        return self.apply(state, op) if self.applicable(state, op) else state

    def successors(self, state: int) -> list[tuple[int, int]]:
        """``(operator, next state)`` for every operator applicable in ``state``, in operator order."""
        out = []
        for op, (pre, neg, add, delete) in enumerate(self._masks):
            if state & pre == pre and not state & neg:
                out.append((op, (state & ~delete) | add))
        return out

    def relaxed_masks(self) -> list[tuple[int, int]]:
        """``(pre, add)`` masks of every operator (for delete-relaxation heuristics)."""
        return [(pre, add) for pre, _, add, _ in self._masks]

    @cached_property
    def relaxed_arrays(self) -> tuple[Any, np.ndarray, Any]:
        """``(pre, pre_count, add)``: ``(A, F)`` sparse 0/1 precondition and add matrices (``float32`` CSR) and
        each operator's number of preconditions (batched delete-relaxation heuristics multiply them; an operator
        touches a few fluents, so sparse products keep large problems, a 30x30 grid's 900 fluents, fast)."""
        from scipy import sparse

        shape = (len(self.operators), len(self.fluents))

        def matrix(column: str) -> Any:
            rows = [a for a, op in enumerate(self.operators) for _ in getattr(op, column)]
            cols = [f for op in self.operators for f in getattr(op, column)]
            return sparse.csr_matrix((np.ones(len(rows), dtype=np.float32), (rows, cols)), shape=shape)

        pre = matrix("pre")
        return pre, np.asarray(pre.sum(axis=1), dtype=np.float32).reshape(-1), matrix("add")

    def bits(self, states: Sequence[int]) -> np.ndarray:
        """``(len(states), n_fluents)`` booleans: the fluents true in each state."""
        n = len(self.fluents)
        width = max(1, (n + 7) // 8)
        raw = np.frombuffer(b"".join(s.to_bytes(width, "big") for s in states), dtype=np.uint8)
        return np.unpackbits(raw.reshape(len(states), width), axis=1)[:, width * 8 - n:].astype(bool)

    def vector(self, state: int) -> np.ndarray:
        """The observation of ``state``: a 0/1 ``int64`` vector in fluent order."""
        n = len(self.fluents)
        return np.array([(state >> (n - 1 - i)) & 1 for i in range(n)], dtype=np.int64)

    def state(self, vector: Sequence[int] | np.ndarray) -> int:
        """The state of an observation vector (inverse of :meth:`vector`)."""
        out = 0
        for v in np.asarray(vector, dtype=np.int64).reshape(-1).tolist():
            out = (out << 1) | int(v != 0)
        return out

    def goal_mask(self, atoms: Sequence[Atom], what: str = "goal") -> int:
        """The state bits a goal's atoms require (static true atoms need none).

        Raises:
            UserError: For an atom that is neither a fluent nor a static fact: no state reaches the goal.
        """
        out = 0
        for atom in atoms:
            if atom in self._fluent_index:
                out |= self.bit(self._fluent_index[atom])
            elif atom not in self.static:
                raise UserError(f"{what}: {atom_text(atom)} holds in no reachable state of this problem")
        return out

    def plan_states(self, plan: Sequence[int], start: int | None = None) -> list[int]:
        """The states a plan visits, start included.

        Raises:
            UserError: If an operator of the plan is not applicable where it is taken.
        """
        states = [self.init if start is None else start]
        for t, op in enumerate(plan):
            if not self.applicable(states[-1], op):
                raise UserError(f"plan step {t}: {self.operators[op].text} is not applicable")
            states.append(self.apply(states[-1], op))
        return states

    def transition_table(self) -> np.ndarray:
        """``(2 ** n_fluents, n_operators)`` successor of every state under every operator (itself where the
        operator is not applicable), rows indexed by state.

        Raises:
            UserError: When there are more than :data:`MAX_TABLE_STATES` states.
        """
        states = self._table_states()
        table = np.empty((len(states), len(self.operators)), dtype=np.int64)
        applicable = self.applicable_table()
        for op, (_, _, add, delete) in enumerate(self._masks):
            table[:, op] = np.where(applicable[:, op], (states & ~delete) | add, states)
        return table

    def applicable_table(self) -> np.ndarray:
        """``(2 ** n_fluents, n_operators)`` whether each operator is applicable in each state, rows by state.

        Raises:
            UserError: When there are more than :data:`MAX_TABLE_STATES` states.
        """
        states = self._table_states()
        out = np.empty((len(states), len(self.operators)), dtype=bool)
        for op, (pre, neg, _, _) in enumerate(self._masks):
            out[:, op] = ((states & pre) == pre) & ((states & neg) == 0)
        return out

    def _table_states(self) -> np.ndarray:
        n_states = 1 << len(self.fluents)
        if n_states > MAX_TABLE_STATES:
            raise UserError(f"this problem has {len(self.fluents)} fluents (2^{len(self.fluents)} states): tables "
                            f"over every state stop at {MAX_TABLE_STATES.bit_length() - 1} fluents")
        return np.arange(n_states, dtype=np.int64)
