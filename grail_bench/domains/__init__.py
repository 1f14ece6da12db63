"""GR domains: one package each, registered in the entry-point group ``grail_bench.domains``.

A domain package ``grail_bench/domains/<name>/`` holds its env, its
demonstrators and the validation of its parameters, and its ``__init__``
exposes ``DOMAIN``, an object satisfying :class:`~grail_bench.task.domain.Domain`
(re-exported here). That ``__init__`` must stay light (plain data and
validation): task cards are parsed on ``import gymnasium``, and only building
an env or a demonstration imports the domain's simulator. Adding a domain
means one package here (or in any installed package), one entry point naming
its ``DOMAIN``, and one task card in ``tasks/``. Domains with a known
demonstrator likelihood also implement :class:`~grail_bench.domains.base.GoalModel`.
"""

from grail_bench.domains.base import GoalModel
from grail_bench.task.domain import Domain, available_domains, get_domain

__all__ = ["Domain", "GoalModel", "available_domains", "get_domain"]
