"""The evaluation harness: observation protocols, metrics, the Bayes ceiling and the run loop.

``evaluate`` is imported lazily: task registration reads the protocol module,
and must not pull in the run loop's heavy imports.
"""

from __future__ import annotations

from typing import Any

__all__ = ["evaluate"]


def __getattr__(name: str) -> Any:
    if name == "evaluate":
        from grail_bench.evaluation.runner import evaluate

        return evaluate
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
