"""What the leaderboard reads of a recognizer without importing it: its published name, default scorer, whether it
is a reference, and its settings as built from stored ones.

Reading these imports the recognizer's module (torch, for most), and building its settings builds one. Both
depend on the code alone, so they are kept in the user's cache folder under a fingerprint of that code: the
content of grail-bench's own sources and the recognizers registered (their names and targets). Any edit, an
upgrade, or a plugin added or removed gives a new fingerprint, so a description is never read from other code.
While a recognizer registered in this process or a plugin outside grail-bench is in play, nothing is kept (its
code is not covered by the fingerprint) and every description is read from the recognizer itself.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

from grail_bench.core.atomic import write_text
from grail_bench.core.errors import UserError
from grail_bench.core.paths import cache_dir
from grail_bench.core.registry import OWN
from grail_bench.recognizers.registry import RECOGNIZERS, UnknownRecognizerError, build, recognizer_info

#: Bumped when what a description holds changes.
SCHEMA = 1
_SOURCES = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Named:
    """A registered recognizer's names.

    Attributes:
        paper_name: The method's published name.
        default_scorer: What it scores with unless told otherwise.
        reference: Whether it is a reference rather than a method.
    """

    paper_name: str
    default_scorer: str
    reference: bool


@dataclass
class _Entries:
    path: Path | None
    named: dict[str, Named | None] = field(default_factory=dict)
    settings: dict[str, dict[str, str | None]] = field(default_factory=dict)
    changed: bool = False


def fingerprint() -> str | None:
    """The digest of the code descriptions depend on, or None when some recognizer's code is not covered by it
    (registered in this process, or a plugin from another package)."""
    targets = RECOGNIZERS.targets()
    if RECOGNIZERS.local_names() or not targets or not all(t.startswith(OWN) for t in targets.values()):
        return None
    digest = hashlib.sha256(json.dumps({"schema": SCHEMA, "targets": targets}, sort_keys=True).encode())
    for path in sorted(_SOURCES.rglob("*.py")):
        digest.update(path.relative_to(_SOURCES).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()[:24]


def _load() -> _Entries:
    try:
        key = fingerprint()
    except OSError:
        key = None
    if key is None:
        return _Entries(None)
    entries = _Entries(cache_dir() / "recognizers" / f"{key}.json")
    try:
        stored = json.loads(entries.path.read_text(encoding="utf-8"))
        entries.named = {name: Named(**n) if n is not None else None for name, n in stored["named"].items()}
        entries.settings = {name: dict(s) for name, s in stored["settings"].items()}
        if not all(isinstance(v, (str, type(None))) for s in entries.settings.values() for v in s.values()) \
                or not all(n is None or (isinstance(n.paper_name, str) and isinstance(n.default_scorer, str)
                                         and isinstance(n.reference, bool)) for n in entries.named.values()):
            raise ValueError("malformed")
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        entries.named, entries.settings = {}, {}  # missing or malformed: described again, from the recognizers
    return entries


_entries: _Entries | None = None
_unkept = _Entries(None)  # while recognizers registered in this process are in play


def _cache() -> _Entries:
    global _entries
    if RECOGNIZERS.local_names():
        return _unkept
    if _entries is None:
        _entries = _load()
    return _entries


def named(recognizer: str) -> Named | None:
    """The recognizer's names, or None when nothing registers it."""
    entries = _cache()
    if recognizer not in entries.named:
        try:
            info = recognizer_info(recognizer)
            entries.named[recognizer] = Named(info.paper_name, info.default_scorer, info.reference)
        except UnknownRecognizerError:
            entries.named[recognizer] = None
        entries.changed = True
    return entries.named[recognizer]


@lru_cache(maxsize=None)
def _built(recognizer: str, stored: str | None) -> str | None:
    try:
        return json.dumps(build(recognizer, json.loads(stored) if stored else None).config, sort_keys=True,
                          default=str)
    except Exception:  # noqa: BLE001 - a plugin gone, or settings refused today
        return None


def settings(recognizer: str, stored: str | None) -> str | None:
    """The recognizer's settings as today's code builds them from ``stored`` (JSON; None: its defaults), as
    canonical JSON; None when it cannot be built (not registered, or the settings are refused)."""
    entries = _cache()
    known = entries.settings.setdefault(recognizer, {})
    key = "" if stored is None else stored  # JSON keys are strings; "" is no JSON document, so it is free
    if key not in known:
        known[key] = _built(recognizer, stored)
        entries.changed = True
    return known[key]


def save() -> None:
    """Keep the descriptions read since the last save (nothing when the cache folder cannot be written)."""
    entries = _cache()
    if entries.path is None or not entries.changed:
        return
    text = json.dumps({"named": {k: v.__dict__ if v is not None else None for k, v in entries.named.items()},
                       "settings": entries.settings}, sort_keys=True)
    try:
        write_text(entries.path, text)
    except (UserError, OSError):
        return
    entries.changed = False


def forget() -> None:
    """Read the cache again on next use (after recognizers are registered or removed in this process)."""
    global _entries
    _entries = None
    _unkept.named.clear()
    _unkept.settings.clear()
    _built.cache_clear()
