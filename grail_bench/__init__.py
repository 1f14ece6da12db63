"""grail-bench: a gymnasium-registered benchmark suite for goal recognition.

Importing the package registers every ``GRAIL/`` task (idempotently). Members
that need torch (the evaluation harness, the recognizers) are imported on
first use, so ``import grail_bench`` stays light.
"""

from __future__ import annotations

from typing import Any

from grail_bench.errors import UserError
from grail_bench.registration import register_envs, task_ids
from grail_bench.task import GRTask, make_task

__version__ = "0.1.0"
__all__ = [
    "FitReport", "GRTask", "Recognizer", "UserError", "ResultsStore", "__version__", "bayes_ceiling", "evaluate", "make_recognizer", "make_task",
    "observe", "register_envs", "task_ids",
]

_LAZY = {
    "Recognizer": "grail_bench.recognizers.base",
    "FitReport": "grail_bench.recognizers.base",
    "make_recognizer": "grail_bench.recognizers.registry",
    "evaluate": "grail_bench.evaluation.runner",
    "observe": "grail_bench.evaluation.protocol",
    "bayes_ceiling": "grail_bench.evaluation.ceiling",
    "ResultsStore": "grail_bench.store",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'grail_bench' has no attribute {name!r}")


register_envs()
