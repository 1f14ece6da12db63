"""Domain specifications: what each domain accepts, without importing it.

Everything here is plain data so that task registration (which runs on
``import gymnasium``) stays light. The heavy modules named by each spec are
imported only when an environment or a demonstration is actually built.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping


@dataclass(frozen=True)
class DomainSpec:
    """Static description of a GR domain.

    Attributes:
        name: Short domain name used in task cards (``domain = "minigrid"``).
        env_factory: ``"module:function"`` building the goal-pinned env.
        demo_generator: ``"module:function"`` producing demonstrations.
        goal_dim: Number of coordinates in a goal.
        env_defaults: Keyword arguments of the env and their defaults.
        regimes: Behaviour regime name -> its parameters and their defaults.
    """

    name: str
    env_factory: str
    demo_generator: str
    goal_dim: int
    env_defaults: Mapping[str, Any] = field(default_factory=dict)
    regimes: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)


def load_object(path: str) -> Callable[..., Any]:
    """Import ``"package.module:attribute"`` and return the attribute."""
    module_name, _, attr = path.partition(":")
    return getattr(importlib.import_module(module_name), attr)


DOMAINS: dict[str, DomainSpec] = {
    "minigrid": DomainSpec(
        name="minigrid",
        env_factory="grail_bench.domains.minigrid:make_env",
        demo_generator="grail_bench.demos.minigrid:generate_demos",
        goal_dim=2,
        env_defaults={
            "size": 9,
            "start": [1, 4],
            "start_dir": 0,
            "obstacles": [[7, 4]],
            "max_steps": 60,
            "fixed_horizon": True,
        },
        regimes={
            "optimal": {},
            # One preferred heading order per goal, e.g. "NE" = north, then east.
            "biased": {"routes": []},
            # turn_pattern: "left-right" or "around-and-back" (grail_bench.demos.minigrid).
            "suboptimal": {"turn_prob": 0.3, "turn_pattern": "left-right"},
        },
    ),
    "panda_reach": DomainSpec(
        name="panda_reach",
        env_factory="grail_bench.domains.panda_reach:make_env",
        demo_generator="grail_bench.demos.panda_reach:generate_demos",
        goal_dim=3,
        env_defaults={"max_steps": 50, "distance_threshold": 0.05, "max_action": 1.0},
        # expert_seed: the SAC expert is part of the demonstrator, trained once per goal with this seed.
        regimes={
            "optimal": {"expert": "sac", "expert_steps": 15000, "expert_seed": 0},
            "gaussian": {"expert": "sac", "expert_steps": 15000, "expert_seed": 0, "sigma": 0.1},
            "uniform": {"expert": "sac", "expert_steps": 15000, "expert_seed": 0, "half_width": 0.1},
        },
    ),
}


def get_domain(name: str) -> DomainSpec:
    """Return the spec of a domain, with a clear error for unknown names."""
    try:
        return DOMAINS[name]
    except KeyError:
        raise ValueError(
            f"unknown domain {name!r}; known domains: {', '.join(sorted(DOMAINS))}"
        ) from None
