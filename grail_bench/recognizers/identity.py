"""A plugin recognizer's identity: what it is, as its results record it.

A recognizer that is not grail-bench's own is identified by the distribution that provides it (its name and
version, read with :mod:`importlib.metadata`) and, unless it was installed from a built wheel, by a hash of its
source. Its source counts as not built when the distribution's ``direct_url.json`` says it was installed from a
local folder (``pip install -e PATH`` or ``pip install PATH``), when the distribution lists no files (no
``RECORD``) or not the plugin's module among them, and when no distribution provides it at all (a module on
``PYTHONPATH``, or one registered in the process). The hash covers the ``.py`` files of the plugin's top-level
package (or its module file alone; a class registered from a notebook, its own source): editing any of them
gives the plugin a new identity.

grail-bench's own recognizers have no identity here: grail-bench's code and version identify them, as the rows'
``versions`` record, so their configurations (and the keys of published rows) are the same as before.
"""

from __future__ import annotations

import hashlib
import importlib.util
import inspect
import json
import sys
from importlib.metadata import PackageNotFoundError, distribution, packages_distributions
from pathlib import Path
from typing import Any

from grail_bench.core.registry import BUILT_IN, OWN
from grail_bench.recognizers.registry import RECOGNIZERS

#: At most this many files are hashed from a plugin's package; a larger tree hashes the plugin's module alone.
MAX_FILES = 2000
#: Hex digits of the SHA-256 a source hash keeps.
LENGTH = 16


def identity(name: str) -> dict[str, Any] | None:
    """The identity of the recognizer registered as ``name``: ``{"distribution", "version"}`` and, for one not
    installed from a built wheel, ``"source"`` (see the module docstring); None for grail-bench's own.

    Raises:
        UnknownRecognizerError: For an unregistered name.
    """
    _, target = RECOGNIZERS.target(name)
    module = target.partition(":")[0] if isinstance(target, str) else getattr(target, "__module__", None)
    if target == BUILT_IN or not module or f"{module}.".startswith(OWN):
        return None
    dist = RECOGNIZERS.distribution(name) or _distribution_of(module)
    out: dict[str, Any] = {"distribution": dist.metadata["Name"] if dist else None,
                           "version": dist.version if dist else None}
    file = _module_file(module)
    if dist is None or not _built(dist, file):
        out["source"] = source_hash(module) or (None if isinstance(target, str) else _object_hash(target))
    return out


def _object_hash(target: Any) -> str | None:
    """SHA-256 (:data:`LENGTH` hex digits) of an object's source where it has no module file (a class defined in
    a notebook or an interactive session); None when its source cannot be read."""
    try:
        text = inspect.getsource(target)
    except (OSError, TypeError):
        return None
    return hashlib.sha256(text.encode()).hexdigest()[:LENGTH]


def _distribution_of(module: str) -> Any | None:
    """The installed distribution holding the top-level package of ``module``, if exactly one does."""
    names = packages_distributions().get(module.split(".")[0], [])
    if len(set(names)) != 1:
        return None
    try:
        return distribution(names[0])
    except PackageNotFoundError:
        return None


def _module_file(module: str) -> Path | None:
    """The file ``module`` was (or would be) loaded from."""
    loaded = sys.modules.get(module)
    origin = getattr(loaded, "__file__", None)
    if origin is None:
        try:
            spec = importlib.util.find_spec(module)
        except (ImportError, ValueError):
            return None
        origin = spec.origin if spec is not None and spec.has_location else None
    return Path(origin).resolve() if origin else None


def _built(dist: Any, file: Path | None) -> bool:
    """Whether ``dist`` was installed from a built wheel and holds ``file`` (see the module docstring)."""
    try:
        direct = json.loads(dist.read_text("direct_url.json") or "{}")
    except ValueError:
        direct = {}
    if "dir_info" in direct:  # an editable install, or one from a local folder
        return False
    files = dist.files
    if files is None or file is None:
        return False
    return any(Path(dist.locate_file(f)).resolve() == file for f in files if str(f).endswith(".py"))


def source_hash(module: str) -> str | None:
    """SHA-256 (:data:`LENGTH` hex digits) of the ``.py`` files of ``module``'s top-level package (its module
    file alone for a single-file module, or a package of more than :data:`MAX_FILES` files); None when no file
    is found."""
    top = module.split(".")[0]
    try:
        spec = importlib.util.find_spec(top)
    except (ImportError, ValueError):
        spec = None
    folders = [Path(p) for p in (spec.submodule_search_locations or [])] if spec is not None else []
    files: list[tuple[str, Path]] = []
    for folder in folders:
        for path in sorted(folder.rglob("*.py")):
            files.append((path.relative_to(folder).as_posix(), path))
            if len(files) > MAX_FILES:
                break
    if not files or len(files) > MAX_FILES:
        own = _module_file(module)
        files = [(own.name, own)] if own is not None and own.is_file() else []
    if not files:
        return None
    digest = hashlib.sha256()
    for name, path in sorted(files):
        digest.update(name.encode() + b"\0")
        try:
            digest.update(path.read_bytes())
        except OSError:
            continue
        digest.update(b"\0")
    return digest.hexdigest()[:LENGTH]
