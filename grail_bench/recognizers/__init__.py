"""Recognizers: the protocol, the plugin registry and the built-in methods.

Built-ins live in submodules that import torch; this package does not, so
listing recognizers stays light.
"""

import os

from grail_bench.paths import cache_dir

# torch creates its compiler cache folder when torch.optim is imported; keep it
# in the suite's cache rather than $TMPDIR (set before any submodule imports torch).
os.environ.setdefault("TORCHINDUCTOR_CACHE_DIR", str(cache_dir() / "torchinductor"))

from grail_bench.recognizers.base import Recognizer, RecognizerError
from grail_bench.recognizers.registry import (
    UnknownRecognizerError,
    available_recognizers,
    make_recognizer,
    register_recognizer,
)

__all__ = [
    "Recognizer",
    "RecognizerError",
    "UnknownRecognizerError",
    "available_recognizers",
    "make_recognizer",
    "register_recognizer",
]
