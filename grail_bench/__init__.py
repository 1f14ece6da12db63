"""grail-bench: a gymnasium-registered benchmark suite for goal recognition.

Importing the package registers every ``GRAIL/`` task (idempotently), and the tasks of the cards
``GRAIL_BENCH_CARDS`` lists and installed packages ship; :func:`load_cards` registers those of any card file or
folder. Members
that need torch (the evaluation harness, the recognizers) are imported on
first use, so ``import grail_bench`` stays light.

The package is built in layers, each importing only the layers below it
(``lint-imports`` checks the contract in ``pyproject.toml``)::

    cli          thin commands: parse, call, map errors
    report       one table model; terminal, Markdown, HTML, plots; reproduce
    harness      planning, sweeps, executors, the store, modes, Bayes ceilings
    recognizers  the contract, registry, scorers and methods   |   domains  one package per domain
    task         task model, cards, registration, observation protocols, the Domain protocol
    stats        metrics, robust aggregates, verdicts against reported values
    core         errors, paths, seeding, plugins, trajectories, cache, provenance, torch/RL helpers
"""

from __future__ import annotations

import importlib
from typing import Any

from grail_bench.core.errors import UserError
from grail_bench.task import GRTask, load_cards, make_task, register_envs, task_ids

__version__ = "0.1.0"
__all__ = [
    "Capabilities", "Domain", "FitDiagnostics", "FitReport", "GRTask", "GoalModel", "ObservationSpec", "PolicyOutput",
    "Recognizer", "RecognizerBase", "ResultsStore", "Scorer", "UserError", "__version__", "bayes_ceiling",
    "evaluate", "load_cards", "make_recognizer", "make_task", "observe", "register_envs", "task_ids",
]

_LAZY = {
    "Capabilities": "grail_bench.recognizers.contract",
    "FitDiagnostics": "grail_bench.recognizers.contract",
    "FitReport": "grail_bench.recognizers.contract",
    "Recognizer": "grail_bench.recognizers.contract",
    "RecognizerBase": "grail_bench.recognizers.contract",
    "make_recognizer": "grail_bench.recognizers.registry",
    "PolicyOutput": "grail_bench.recognizers.scoring",
    "Scorer": "grail_bench.recognizers.scoring",
    "Domain": "grail_bench.task.domain",
    "GoalModel": "grail_bench.domains.base",
    "ObservationSpec": "grail_bench.task.observation",
    "observe": "grail_bench.task.observation",
    "evaluate": "grail_bench.harness.api",
    "bayes_ceiling": "grail_bench.harness.ceiling",
    "ResultsStore": "grail_bench.harness.store",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'grail_bench' has no attribute {name!r}")


register_envs()
