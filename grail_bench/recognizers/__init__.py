"""The recognizer layer: the contract, the plugin registry, the scorers and the built-in methods.

Built-ins live in submodules that import torch; this package does not, so
listing recognizers stays light.
"""

from grail_bench.recognizers.contract import (
    Capabilities,
    FitDiagnostics,
    FitReport,
    Recognizer,
    RecognizerBase,
    RecognizerError,
    capabilities,
)
from grail_bench.recognizers.registry import (
    UnknownRecognizerError,
    available_recognizers,
    build,
    make_recognizer,
    recognizer_info,
    register_recognizer,
)

__all__ = [
    "Capabilities",
    "FitDiagnostics",
    "FitReport",
    "Recognizer",
    "RecognizerBase",
    "RecognizerError",
    "UnknownRecognizerError",
    "available_recognizers",
    "build",
    "capabilities",
    "make_recognizer",
    "recognizer_info",
    "register_recognizer",
]
