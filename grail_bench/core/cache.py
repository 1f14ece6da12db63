"""On-disk cache of trained models, written and read by grail-bench only.

A model is a torch ``state_dict`` (saved with ``torch.save``, loaded with
``weights_only=True``) or a set of numpy arrays (``.npz``, loaded with
``allow_pickle=False``): nothing is ever unpickled. Beside it, a JSON sidecar
holds the key it was trained for and a SHA-256 of the model file. A missing,
corrupt or mismatched entry is reported in one line and the caller retrains;
nothing is ever silently reused.

Concurrent processes (a parallel sweep) share the cache safely: each key has a
lock file, held while an entry is read or trained and written, so a second
process asking for a model being trained waits and then reuses it; the model
and its sidecar are each written to a temporary name and moved into place
(:mod:`grail_bench.core.atomic`). An entry read back is checked before use: a
malformed sidecar, a model that is not named arrays, an array holding NaN, or
one the caller's ``check`` refuses (a wrong key or shape) is discarded with one
warning naming it, and retrained.
"""

from __future__ import annotations

import hashlib
import json
import math
import pickle
import time
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from grail_bench.core.atomic import write_text, write_with
from grail_bench.core.paths import cache_dir


class CacheWarning(UserWarning):
    """A cached model was unusable and is being retrained."""


def key_digest(key: dict[str, Any]) -> str:
    """Stable short hash of a JSON-able cache key."""
    return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:20]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _save_torch(state: dict[str, Any], path: Path) -> None:
    import torch

    torch.save(state, path)


def _load_torch(path: Path) -> dict[str, Any]:
    import torch

    return torch.load(path, map_location="cpu", weights_only=True)


def _save_arrays(arrays: dict[str, Any], path: Path) -> None:
    import numpy as np

    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def _load_arrays(path: Path) -> dict[str, Any]:
    import numpy as np

    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


class Unusable(ValueError):
    """A cache entry read back is not what grail-bench wrote (the reason is the message)."""


def _sidecar(meta: Path) -> dict[str, Any]:
    """An entry's sidecar, checked to be the JSON object grail-bench writes."""
    info = json.loads(meta.read_text(encoding="utf-8"))
    if not isinstance(info, dict) or not isinstance(info.get("sha256"), str):
        raise Unusable("its sidecar is malformed")
    seconds = info.get("train_seconds", 0.0)
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not math.isfinite(seconds) or seconds < 0:
        raise Unusable("its sidecar's training time is malformed")
    if not isinstance(info.get("extra") or {}, dict):
        raise Unusable("its sidecar's extra data is malformed")
    return info


def _check_state(state: Any) -> None:
    """Refuse a loaded model that is not named arrays or tensors, or holds a NaN."""
    import numpy as np

    if not isinstance(state, dict) or not all(isinstance(name, str) for name in state):
        raise Unusable("it is not a set of named arrays")
    for name, value in state.items():
        if hasattr(value, "detach"):  # a torch tensor
            value = value.detach().cpu().numpy() if value.dtype.is_floating_point else None
        elif isinstance(value, dict):
            _check_state(value)
            continue
        elif not hasattr(value, "dtype"):
            continue  # a number or a setting kept beside the weights
        if value is not None and value.dtype.kind == "O":
            raise Unusable(f"its array {name!r} holds objects")
        if value is not None and value.dtype.kind in "fc" and bool(np.isnan(value).any()):
            raise Unusable(f"its array {name!r} holds NaN")


class Busy(Exception):
    """Another process holds the entry's lock (it is training that model now)."""


@dataclass(frozen=True)
class Cached:
    """A model from the cache or freshly trained.

    Attributes:
        state: The ``state_dict`` or named arrays.
        seconds: What training took (now, or when the cached model was trained).
        reused: Whether it was read from the cache.
        extra: JSON-able data the training returned beside the model (e.g. its training curves), kept in
            the sidecar; empty for entries written before it was kept.
    """

    state: dict[str, Any]
    seconds: float
    reused: bool
    extra: dict[str, Any] = field(default_factory=dict)


def _paths(kind: str, key: dict[str, Any], suffix: str, root: Path | None) -> tuple[Path, Path, Path]:
    """An entry's model file, sidecar and lock file (its folder created)."""
    folder = (root or cache_dir()) / kind
    folder.mkdir(parents=True, exist_ok=True)
    digest = key_digest(key)
    return folder / f"{digest}{suffix}", folder / f"{digest}.json", folder / f"{digest}.lock"


def _cached(kind: str, key: dict[str, Any], train: Callable[[], Any], suffix: str,
            save: Callable[[dict[str, Any], Path], None], load: Callable[[Path], dict[str, Any]],
            root: Path | None, wait: bool = True, spent: float = 0.0,
            check: Callable[[dict[str, Any]], None] | None = None) -> Cached:
    from filelock import FileLock, Timeout

    model, meta, lock_file = _paths(kind, key, suffix, root)
    lock = FileLock(str(lock_file))
    try:
        lock.acquire(timeout=-1 if wait else 0)
    except Timeout:
        raise Busy(str(model)) from None
    try:
        if model.exists() or meta.exists():
            problem = None
            try:
                info = _sidecar(meta)
                if info.get("key") != json.loads(json.dumps(key, sort_keys=True, default=str)):
                    problem = "it was trained for another configuration"
                elif info.get("sha256") != _sha256(model):
                    problem = "its weights do not match their checksum"
                else:
                    state = load(model)
                    _check_state(state)
                    if check is not None:
                        try:
                            check(state)
                        except (ValueError, RuntimeError, KeyError, TypeError, IndexError) as exc:
                            raise Unusable(" ".join(str(exc).split())[:300] or type(exc).__name__) from None
                    return Cached(state, float(info.get("train_seconds", 0.0)), True, dict(info.get("extra") or {}))
            except Unusable as exc:
                problem = str(exc)
            except (OSError, ValueError, RuntimeError, EOFError, KeyError, TypeError, IndexError,
                    pickle.UnpicklingError, zipfile.BadZipFile) as exc:
                problem = f"it cannot be read ({type(exc).__name__})"
            warnings.warn(f"cached model {model} is unusable: {problem}; retraining", CacheWarning, stacklevel=3)
        start = time.perf_counter()
        state, extra = _split(train())
        seconds = spent + time.perf_counter() - start
        meta.unlink(missing_ok=True)  # a model without its sidecar reads as unusable, never as another's
        write_with(model, lambda tmp: save(state, tmp))
        sidecar = json.dumps({"key": key, "sha256": _sha256(model), "train_seconds": seconds, "extra": extra},
                             sort_keys=True, default=str)
        write_text(meta, sidecar)
    finally:
        lock.release()
    return Cached(state, seconds, False, extra)


def _split(trained: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """A training function's ``state`` or ``(state, extra)``."""
    if isinstance(trained, tuple):
        state, extra = trained
        return state, dict(extra)
    return trained, {}


def cached(kind: str, key: dict[str, Any], train: Callable[[], Any], *, arrays: bool = False,
           root: Path | None = None, wait: bool = True, spent: float = 0.0,
           check: Callable[[dict[str, Any]], None] | None = None) -> Cached:
    """Load a cached model for ``key`` or train, save and return a new one, with what training returned beside it.

    Args:
        kind: Folder under the cache (e.g. ``"panda-sac-expert"``).
        key: Everything the model depends on (JSON-able).
        train: Produces the model (a torch ``state_dict``, or named numpy arrays with ``arrays``), or
            ``(model, extra)`` with JSON-able ``extra`` kept beside it.
        arrays: Named numpy arrays (``.npz``) rather than a ``state_dict`` (``.pt``).
        root: Cache root (default :func:`grail_bench.core.paths.cache_dir`).
        wait: When another process is training this model, wait for it (default) or raise :class:`Busy`.
        spent: Seconds already spent training this model before the call (e.g. its share of a batch of
            models trained together), recorded with what ``train`` takes when it runs.
        check: Called on a model read from the cache; raising ``ValueError`` (its message the reason) or
            ``RuntimeError`` (e.g. ``load_state_dict`` on a wrong shape) discards the entry, warned in one line,
            and retrains. A model holding NaN, or that is not named arrays, is discarded without it.

    Raises:
        grail_bench.core.atomic.WriteError: The trained model could not be written (one line; nothing
            half-written is left).
    """
    if arrays:
        return _cached(kind, key, train, ".npz", _save_arrays, _load_arrays, root, wait, spent, check)
    return _cached(kind, key, train, ".pt", _save_torch, _load_torch, root, wait, spent, check)


def needs_training(kind: str, key: dict[str, Any], *, arrays: bool = False, root: Path | None = None) -> bool:
    """Whether :func:`cached` would train ``key``'s model now: no entry for ``key`` is stored and no other
    process is training it. A quick look (the sidecar's key, not the checksum; the lock taken for an instant):
    :func:`cached` still decides."""
    from filelock import FileLock, Timeout

    model, meta, lock_file = _paths(kind, key, ".npz" if arrays else ".pt", root)
    if model.exists() and meta.exists():
        try:
            if _sidecar(meta).get("key") == json.loads(json.dumps(key, sort_keys=True, default=str)):
                return False
        except (OSError, ValueError):
            pass
    lock = FileLock(str(lock_file))
    try:
        lock.acquire(timeout=0)
    except Timeout:
        return False  # another process is training it
    lock.release()
    return True


def cached_state_dict(kind: str, key: dict[str, Any], train: Callable[[], dict[str, Any]],
                      root: Path | None = None, wait: bool = True,
                      check: Callable[[dict[str, Any]], None] | None = None) -> tuple[dict[str, Any], float]:
    """:func:`cached` for a torch ``state_dict``: ``(state_dict, seconds)``."""
    entry = cached(kind, key, train, root=root, wait=wait, check=check)
    return entry.state, entry.seconds


def cached_arrays(kind: str, key: dict[str, Any], train: Callable[[], dict[str, Any]],
                  root: Path | None = None,
                  check: Callable[[dict[str, Any]], None] | None = None) -> tuple[dict[str, Any], float, bool]:
    """:func:`cached` for named numpy arrays (``.npz``): ``(arrays, seconds, reused)``."""
    entry = cached(kind, key, train, arrays=True, root=root, check=check)
    return entry.state, entry.seconds, entry.reused
