"""On-disk cache of trained models, written and read by grail-bench only.

A model is a torch ``state_dict`` saved with ``torch.save`` and loaded with
``weights_only=True`` (no unpickling), beside a JSON sidecar holding the key it
was trained for and a SHA-256 of the weights file. A missing, corrupt or
mismatched entry is reported in one line and the caller retrains; nothing is
ever silently reused.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import warnings
from pathlib import Path
from typing import Any, Callable

from grail_bench.paths import cache_dir


class CacheWarning(UserWarning):
    """A cached model was unusable and is being retrained."""


def key_digest(key: dict[str, Any]) -> str:
    """Stable short hash of a JSON-able cache key."""
    return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:20]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def cached_state_dict(kind: str, key: dict[str, Any], train: Callable[[], dict[str, Any]],
                      root: Path | None = None) -> tuple[dict[str, Any], float]:
    """Load a cached ``state_dict`` for ``key`` or train, save and return a new one.

    Args:
        kind: Folder under the cache (e.g. ``"panda-sac-expert"``).
        key: Everything the model depends on (JSON-able).
        train: Produces the ``state_dict`` when the cache cannot serve it.
        root: Cache root (default :func:`grail_bench.paths.cache_dir`).

    Returns:
        ``(state_dict, seconds)``: ``seconds`` is what training took, when it
        happened now or when the cached model was trained.
    """
    import time

    import torch

    folder = (root or cache_dir()) / kind
    digest = key_digest(key)
    weights, meta = folder / f"{digest}.pt", folder / f"{digest}.json"
    if weights.exists() or meta.exists():
        problem = None
        try:
            info = json.loads(meta.read_text(encoding="utf-8"))
            if info.get("key") != json.loads(json.dumps(key, sort_keys=True, default=str)):
                problem = "it was trained for another configuration"
            elif info.get("sha256") != _sha256(weights):
                problem = "its weights do not match their checksum"
            else:
                state = torch.load(weights, map_location="cpu", weights_only=True)
                return state, float(info.get("train_seconds", 0.0))
        except (OSError, ValueError, RuntimeError, EOFError, pickle.UnpicklingError) as exc:
            problem = f"it cannot be read ({type(exc).__name__})"
        warnings.warn(f"cached model {weights} is unusable: {problem}; retraining", CacheWarning, stacklevel=2)
    start = time.perf_counter()
    state = train()
    seconds = time.perf_counter() - start
    folder.mkdir(parents=True, exist_ok=True)
    tmp = weights.with_suffix(f".tmp{os.getpid()}")
    torch.save(state, tmp)
    os.replace(tmp, weights)  # atomic: a crash never leaves a half-written model under the real name
    meta.write_text(json.dumps({"key": key, "sha256": _sha256(weights), "train_seconds": seconds}, sort_keys=True,
                               default=str), encoding="utf-8")
    return state, seconds
