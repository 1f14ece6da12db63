"""Recognizers: the protocol, the plugin registry and the built-in methods.

Built-ins live in submodules that import torch; this package does not, so
listing recognizers stays light.
"""

from grail_bench.recognizers.base import FitReport, Recognizer, RecognizerError
from grail_bench.recognizers.registry import (
    UnknownRecognizerError,
    available_recognizers,
    make_recognizer,
    register_recognizer,
)

__all__ = [
    "FitReport",
    "Recognizer",
    "RecognizerError",
    "UnknownRecognizerError",
    "available_recognizers",
    "make_recognizer",
    "register_recognizer",
]
