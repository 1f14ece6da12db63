"""The evaluation harness: protocol, metrics and the run loop."""

from grail_bench.evaluation.runner import evaluate

__all__ = ["evaluate"]
