"""A goal-recognition problem in the dataset's terms, and its grounded model.

:class:`GRProblem` holds what one archive of Pereira et al.'s dataset holds
(domain, template with ``<HYPOTHESIS>``, candidate goals, the true one, the
observed actions) and grounds it once, for every candidate goal at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from grail_bench.core.errors import UserError
from grail_bench.domains.symbolic.pddl_text import Atom, atom_text
from grail_bench.domains.symbolic.strips import StripsModel

PLACEHOLDER = "<HYPOTHESIS>"


@dataclass(frozen=True)
class GRProblem:
    """One goal-recognition problem.

    Attributes:
        name: Its name (the archive's, or the generator's).
        domain_pddl: ``domain.pddl``, verbatim.
        template_pddl: ``template.pddl``: the problem with ``<HYPOTHESIS>`` in place of the goal's atoms.
        hypotheses: The candidate goals (``hyps.dat``), each a conjunction of lower-case atoms.
        real_hyp: The true goal (``real_hyp.dat``).
        observations: The observed ground actions (``obs.dat``), in order.
    """

    name: str
    domain_pddl: str
    template_pddl: str
    hypotheses: tuple[tuple[Atom, ...], ...]
    real_hyp: tuple[Atom, ...]
    observations: tuple[Atom, ...]

    def __post_init__(self) -> None:
        if PLACEHOLDER not in self.template_pddl:
            raise UserError(f"{self.name}: template.pddl has no {PLACEHOLDER} where the goal goes")
        if not self.hypotheses:
            raise UserError(f"{self.name}: hyps.dat lists no candidate goal")

    def problem_pddl(self, goal: int) -> str:
        """The template with candidate goal ``goal``'s atoms in place of ``<HYPOTHESIS>``."""
        return self.template_pddl.replace(PLACEHOLDER, " ".join(atom_text(a) for a in self.hypotheses[goal]))

    @cached_property
    def model(self) -> StripsModel:
        """The grounded model shared by every candidate goal.

        Raises:
            UserError: For PDDL that does not parse or lies outside the subset, or goals naming unknown
                predicates or objects.
        """
        from grail_bench.domains.symbolic.grounding import ground
        from grail_bench.domains.symbolic.pddl_text import parse_domain, parse_problem

        domain = parse_domain(self.domain_pddl)
        lifted = parse_problem(self.problem_pddl(0), domain)
        try:
            return ground(domain, lifted, self.hypotheses)
        except UserError as err:
            raise UserError(f"{self.name}: {err}") from None

    @cached_property
    def goal_masks(self) -> tuple[int, ...]:
        """Per candidate goal, the state bits it requires."""
        return tuple(self.model.goal_mask(h, f"{self.name}: hypothesis {i}") for i, h in enumerate(self.hypotheses))

    @property
    def real_index(self) -> int:
        """Index of the true goal among the hypotheses.

        Raises:
            UserError: If real_hyp.dat is none of them.
        """
        for i, hyp in enumerate(self.hypotheses):
            if set(hyp) == set(self.real_hyp):
                return i
        raise UserError(f"{self.name}: real_hyp.dat {', '.join(map(atom_text, self.real_hyp))} is not among hyps.dat")

    def observed_operators(self) -> list[int]:
        """The observed actions as operator indices of :attr:`model`.

        Raises:
            UserError: For an observed action that is no reachable ground operator.
        """
        return [self.model.operator_index(a) for a in self.observations]
