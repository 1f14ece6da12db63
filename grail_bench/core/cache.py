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
and its sidecar are each written to a temporary name and moved into place.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import time
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

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


def _write_atomic(path: Path, write: Callable[[Path], None]) -> None:
    """Write through a temporary name, then move into place (never a half-written file under ``path``)."""
    tmp = path.with_name(f"{path.name}.tmp{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


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
            root: Path | None, wait: bool = True, spent: float = 0.0) -> Cached:
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
                info = json.loads(meta.read_text(encoding="utf-8"))
                if info.get("key") != json.loads(json.dumps(key, sort_keys=True, default=str)):
                    problem = "it was trained for another configuration"
                elif info.get("sha256") != _sha256(model):
                    problem = "its weights do not match their checksum"
                else:
                    return Cached(load(model), float(info.get("train_seconds", 0.0)), True, dict(info.get("extra") or {}))
            except (OSError, ValueError, RuntimeError, EOFError, KeyError, pickle.UnpicklingError,
                    zipfile.BadZipFile) as exc:
                problem = f"it cannot be read ({type(exc).__name__})"
            warnings.warn(f"cached model {model} is unusable: {problem}; retraining", CacheWarning, stacklevel=3)
        start = time.perf_counter()
        state, extra = _split(train())
        seconds = spent + time.perf_counter() - start
        _write_atomic(model, lambda tmp: save(state, tmp))
        sidecar = json.dumps({"key": key, "sha256": _sha256(model), "train_seconds": seconds, "extra": extra},
                             sort_keys=True, default=str)
        _write_atomic(meta, lambda tmp: tmp.write_text(sidecar, encoding="utf-8"))
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
           root: Path | None = None, wait: bool = True, spent: float = 0.0) -> Cached:
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
    """
    if arrays:
        return _cached(kind, key, train, ".npz", _save_arrays, _load_arrays, root, wait, spent)
    return _cached(kind, key, train, ".pt", _save_torch, _load_torch, root, wait, spent)


def needs_training(kind: str, key: dict[str, Any], *, arrays: bool = False, root: Path | None = None) -> bool:
    """Whether :func:`cached` would train ``key``'s model now: no entry for ``key`` is stored and no other
    process is training it. A quick look (the sidecar's key, not the checksum; the lock taken for an instant):
    :func:`cached` still decides."""
    from filelock import FileLock, Timeout

    model, meta, lock_file = _paths(kind, key, ".npz" if arrays else ".pt", root)
    if model.exists() and meta.exists():
        try:
            if json.loads(meta.read_text(encoding="utf-8")).get("key") == json.loads(
                    json.dumps(key, sort_keys=True, default=str)):
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
                      root: Path | None = None, wait: bool = True) -> tuple[dict[str, Any], float]:
    """:func:`cached` for a torch ``state_dict``: ``(state_dict, seconds)``."""
    entry = cached(kind, key, train, root=root, wait=wait)
    return entry.state, entry.seconds


def cached_arrays(kind: str, key: dict[str, Any], train: Callable[[], dict[str, Any]],
                  root: Path | None = None) -> tuple[dict[str, Any], float, bool]:
    """:func:`cached` for named numpy arrays (``.npz``): ``(arrays, seconds, reused)``."""
    entry = cached(kind, key, train, arrays=True, root=root)
    return entry.state, entry.seconds, entry.reused
