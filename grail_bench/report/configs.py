"""Which configuration a stored run is: a method's canonical one, a named variant, or archived.

A recognizer's **canonical** configuration is its default today, scored with its own scorer, and it is named
as its method is published (``BC-GRAIL``, ``GRAQL``, ``DRACO``; a plugin's own name). The main boards and
every summary show canonical configurations only.

Any other configuration today's code still runs as stored is a **named variant**, labelled by how it differs
from the canonical one: ``GAIL-GRAIL · total_timesteps 20 000``, ``BC-GRAIL · off_support stay``,
``BC-GRAIL · occupancy`` (another scorer), never by a hash.

A configuration today's code would not store as it was stored (planned again from its task and settings, its
hash differs: a setting or task parameter added, removed or refused since, such as a default that changed)
was run by an earlier version: it is **archived**, still linked to its runs, out of boards and summaries.
Hashes stay in the records for provenance. A plugin recognizer's configuration records its identity
(distribution, version and, unless installed from a built wheel, a hash of its source): runs of an earlier
version or source of a plugin are archived too.

Runs on demonstrations from a dataset (``run --demos``) are a configuration of their own, labelled by the
dataset's name (``toy · demos my-dataset``): canonical or a named variant as the recognizer's settings say, never
archived for the dataset (today's code is checked against the run with the dataset as the run recorded it).

Runs of a user's own task not known in the reading process (a card not loaded, a problem set not given) cannot be planned
again: they are never archived for that. They are judged by what can still be judged, the recognizer's settings
as today's code builds them and a plugin's identity: archived where either differs, else canonical or a named
variant as above (:func:`not_loaded`; the commands that read them say so in one line).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Iterable, Literal

from grail_bench.harness.planning import config_hash, fitted_config
from grail_bench.recognizers import descriptions
from grail_bench.recognizers.identity import identity
from grail_bench.task import find_task
from grail_bench.task.external import RESERVED

Kind = Literal["canonical", "variant", "archived"]

#: How a name and its differences are joined in a label.
SEPARATOR = " · "


@dataclass(frozen=True)
class Configuration:
    """A stored configuration as the leaderboard names it.

    Attributes:
        kind: ``canonical``, ``variant`` or ``archived`` (see the module docstring).
        method: The method's published name (``BC-GRAIL``).
        changes: The settings that differ from the canonical configuration, ``(name, value)`` sorted by name
            (a setting the run did not store, or set to None as not in play, has value None; labels omit those).
        scorer: The scorer when it is not the method's own, else None.
        config_hash: The stored configuration's hash (archived labels carry its first 6 characters).
        recognizer: The registered recognizer name.
        submitted_by: The lab whose submission the runs came from (merged from published results, not run
            here; labels end ``submitted by LAB``), else None.
        dataset: The name of the dataset the runs took their demonstrations from (``run --demos``; labels end
            ``demos NAME``), else None.
        note: What else differs from today's, where no setting does: an archived plugin's earlier version or
            source (``version 0.1, now 0.2``).
    """

    kind: Kind
    method: str
    changes: tuple[tuple[str, Any], ...] = ()
    scorer: str | None = None
    config_hash: str = ""
    recognizer: str = ""
    submitted_by: str | None = None
    dataset: str | None = None
    note: str = ""

    @property
    def label(self) -> str:
        """``BC-GRAIL``, ``GAIL-GRAIL · total_timesteps 20 000 · loglik``, ``BC-GRAIL · demos my-dataset`` or
        ``AIRL-GRAIL · archived 7318c1``."""
        parts = [self.method, *(f"{k} {value_text(v)}" for k, v in self.changes if v is not None)]
        if self.scorer:
            parts.append(self.scorer)
        if self.kind == "archived":
            parts = [self.method, f"archived {self.config_hash[:6]}", *([self.scorer] if self.scorer else [])]
        if self.dataset is not None:
            parts.append(f"demos {self.dataset}")
        if self.submitted_by is not None:
            parts.append(f"submitted by {self.submitted_by}")
        return SEPARATOR.join(parts)

    @property
    def canonical(self) -> bool:
        return self.kind == "canonical"

    @property
    def reference(self) -> bool:
        """A reference (its recognizer says so, as the demonstrator does), shown beside the methods but never
        ranked or summarised."""
        return _is_reference(self.recognizer)

    @property
    def changes_text(self) -> str:
        """The settings that differ from today's default, ``n_epochs 25, off_support stay`` (a setting the run
        did not store reads ``n_epochs unset``); ``none`` when only the task or the hashed fields differ."""
        parts = [f"{k} {value_text(v) if v is not None else 'unset'}" for k, v in self.changes]
        return ", ".join(parts or ([self.note] if self.note else [])) or "none"


def value_text(value: Any) -> str:
    """A setting's value as labels show it: ``40 000``, ``stay``, ``0.001``, ``[64, 64]``."""
    if isinstance(value, bool) or value is None:
        return json.dumps(value)
    if isinstance(value, int):
        return f"{value:,}".replace(",", " ")
    if isinstance(value, str):
        return value
    return json.dumps(value, sort_keys=True)


@lru_cache(maxsize=None)
def method_of(recognizer: str) -> tuple[str, str | None]:
    """``(published name, own scorer)`` of a recognizer (its own name and no scorer when not registered)."""
    named = descriptions.named(recognizer)
    return (recognizer, None) if named is None else (named.paper_name, named.default_scorer)


@lru_cache(maxsize=None)
def _is_reference(recognizer: str) -> bool:
    named = descriptions.named(recognizer)
    return named is not None and named.reference


@lru_cache(maxsize=None)
def _settings(recognizer: str, stored: str | None) -> str | None:
    """The recognizer's settings as today's code builds them from ``stored`` (JSON; None: its defaults), as
    canonical JSON; None when it cannot be built (not registered, or the settings are refused: the configuration
    is archived)."""
    return descriptions.settings(recognizer, stored)


@lru_cache(maxsize=None)
def _current_hash(task_id: str, params: str, recognizer: str, settings: str, demos: str = "{}") -> str | None:
    task = find_task(task_id, json.loads(params))
    if task is None:
        return None
    return config_hash(fitted_config(task, recognizer, json.loads(settings), demos=json.loads(demos)))


def not_loaded(task_id: str) -> bool:
    """Whether a task is a user's own (a card's from outside grail-bench, whose IDs never take ``GRAIL/``, or a
    problem set's, ``symbolic:<name>``) that is not known in this process: its card not loaded (``--cards``,
    ``GRAIL_BENCH_CARDS``), its problem set not read (``--task PATH``). Its rows are named by their recognizer's
    settings and identity alone (see the module docstring); a ``GRAIL/`` task no longer shipped is an earlier
    version's."""
    return not task_id.startswith(RESERVED) and find_task(task_id) is None


def _canonical_json(value: Any) -> str:
    return json.dumps(value, sort_keys=True, default=str)


ConfigKey = tuple[str, str, str, str]  # task, recognizer, scorer, config hash: what a configuration's records share


def config_key(record: Any) -> ConfigKey:
    """The key a record's configuration is known by (its hash covers its task's parameters and settings)."""
    return record.task, record.recognizer, record.scorer, record.config_hash


def configurations(records: Iterable[Any]) -> dict[ConfigKey, Configuration]:
    """Every distinct configuration of ``records`` named once, by :func:`config_key`."""
    out: dict[ConfigKey, Configuration] = {}
    for r in records:
        key = config_key(r)
        if key not in out:
            out[key] = configuration(r)
    descriptions.save()  # the recognizers described here are not imported next time
    return out


def configuration(record: Any) -> Configuration:
    """Name a stored configuration (any record or row with ``task``, ``recognizer``, ``scorer``,
    ``config_hash``, ``task_params`` and ``recognizer_config``)."""
    method, own = method_of(record.recognizer)
    scorer = None if record.scorer in (own, "default") or own is None else record.scorer
    source = getattr(record, "source", None)
    submitted_by = str(source.get("lab", "?")) if source else None
    stored = _canonical_json(record.recognizer_config)
    demos = dict(getattr(record, "dataset", None) or {})
    dataset = (demos.get("dataset") or f"dataset {demos['demos'][:6]}") if demos.get("demos") else None
    if own is None:  # a plugin no longer installed: nothing to compare with, its runs shown as they are
        return Configuration("variant", method, tuple(sorted(record.recognizer_config.items())), scorer,
                             record.config_hash, record.recognizer, submitted_by, dataset)
    rebuilt, default = _settings(record.recognizer, stored), _settings(record.recognizer, None)
    note = _identity_note(record.recognizer, _canonical_json(getattr(record, "identity", None) or {}))
    if not not_loaded(record.task):
        current = rebuilt is not None and _current_hash(record.task, _canonical_json(record.task_params),
                                                        record.recognizer, rebuilt,
                                                        _canonical_json(demos)) == record.config_hash
    else:  # its task is not known here: judged by what still can be, the settings as built today and the plugin
        current = rebuilt == stored and not note
    changes = _changes(record.recognizer_config, default)
    kind: Kind = "archived" if not current else "canonical" if not changes and scorer is None else "variant"
    return Configuration(kind, method, changes, scorer, record.config_hash, record.recognizer, submitted_by,
                         dataset, note if kind == "archived" else "")


@lru_cache(maxsize=None)
def _identity_note(recognizer: str, stored: str) -> str:
    """How a plugin's identity as its runs recorded it (``stored``, JSON) differs from today's: its version, or
    its source; empty for grail-bench's own recognizers and where nothing differs."""
    try:
        today = identity(recognizer)
    except Exception:  # noqa: BLE001 - a plugin gone: nothing to compare with
        return ""
    before = json.loads(stored)
    if today is None or before == today:
        return ""
    if not before:
        return "run before plugin identities were recorded"
    if before.get("version") != today.get("version"):
        return f"version {before.get('version')}, now {today.get('version')}"
    return "an earlier source" if before.get("source") != today.get("source") else "another distribution"


def _changes(stored: dict[str, Any], default_json: str | None) -> tuple[tuple[str, Any], ...]:
    """The settings where ``stored`` differs from the default (a setting it lacks has value None)."""
    default = json.loads(default_json) if default_json else {}
    keys = sorted(set(stored) | set(default))
    return tuple((k, stored.get(k)) for k in keys if _canonical_json(stored.get(k)) != _canonical_json(default.get(k)))
