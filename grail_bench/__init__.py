"""grail-bench: a gymnasium-registered benchmark suite for goal recognition.

Importing the package registers every ``GRAIL/`` task (idempotently). Heavy
members (recognizers, the evaluation harness) are imported on first use.
"""

from __future__ import annotations

from grail_bench.registration import register_envs, task_ids
from grail_bench.task import GRTask, make_task

__version__ = "0.1.0"
__all__ = ["GRTask", "make_task", "register_envs", "task_ids", "__version__"]

register_envs()
