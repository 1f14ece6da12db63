"""Minari datasets read as a task's demonstrations (a card's ``demos`` field, ``run --demos``).

A source is a dataset folder, a folder of datasets (those :mod:`grail_bench.task.export`
writes: the one exported with the run's seed is read), or a dataset ID under
``$MINARI_DATASETS_PATH``. Every input is checked before a demonstration is used:

* a dataset exported by grail-bench records, under ``grail_bench`` in its
  metadata, the task ID, regime, parameters, env parameters and goals it was
  made for: each must be the task's (the first that differs is named);
* the dataset's observation and action spaces must be the task env's, and
  every episode's observations and actions must lie within them;
* episodes need a ``goal`` and a ``split`` (``train`` or ``test``) in their
  metadata: every task goal with at least one ``train`` and one ``test``
  episode, the same number of training episodes per goal. Datasets recorded
  elsewhere (no ``grail_bench`` metadata) are checked by these two alone.

A task reads each episode's observations, actions and ``is_success`` infos;
rewards, terminations, truncations and the other infos are not read, so
exports written before they held the env's rewards and ``after_goal`` read
as they did.

Minari's HDF5 storage holds arrays, JSON and attributes only: loading unpickles
nothing. Minari is imported only when a dataset is read or written
(``pip install 'grail-bench[minari]'``, which ``make test`` installs).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Demos, Goal
from grail_bench.task.domain import stored_params
from grail_bench.task.overrides import freeze

if TYPE_CHECKING:
    from grail_bench.task.model import GRTask

SPLITS = ("train", "test")
METADATA = "grail_bench"  # the dataset metadata key grail-bench's exports write


def minari_module() -> Any:
    """Minari, imported.

    Raises:
        UserError: When it is not installed, naming the extra that installs it.
    """
    try:
        import minari
    except ImportError:
        raise UserError("Minari datasets need minari: pip install 'grail-bench[minari]'") from None
    return minari


@dataclass(frozen=True)
class Loaded:
    """A dataset's demonstrations as a task takes them.

    Attributes:
        demos: Per goal, the training demonstrations first, then the test ones.
        n_train: Training demonstrations per goal.
        n_demos: Demonstrations per goal.
        digest: SHA-256 of every episode's observations, actions and labels (it keys stored results).
        seed: The seed it was exported with (None for datasets recorded elsewhere).
    """

    demos: Demos
    n_train: int
    n_demos: int
    digest: str
    seed: int | None


def _datasets_in(source: str) -> list[Path]:
    """The dataset folders a source names (a dataset, a folder of datasets, or an ID)."""
    minari_module()
    path = Path(source).expanduser()
    if path.is_dir():
        if (path / "data" / "metadata.json").is_file():
            return [path / "data"]
        if (path / "metadata.json").is_file():
            return [path]
        found = sorted(p.parent for p in path.rglob("metadata.json") if p.parent.name == "data")
        if found:
            return found
        raise UserError(f"{source} holds no Minari dataset (no data/metadata.json below it)")
    from minari.storage import get_dataset_path

    candidate = get_dataset_path(source) / "data"
    if (candidate / "metadata.json").is_file():
        return [candidate]
    raise UserError(f"no Minari dataset {source!r}: neither a folder nor a dataset ID under $MINARI_DATASETS_PATH")


def source_digest(source: str) -> str:
    """SHA-256 (16 hex digits) of the data files of every dataset a source names: what keys results run on it."""
    digest = hashlib.sha256()
    for folder in _datasets_in(source):
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                digest.update(path.name.encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def check_seeds(source: str, seeds: Sequence[int]) -> None:
    """Refuse seeds that a folder of per-seed datasets has no dataset for (a single dataset serves every seed).

    Raises:
        UserError: Naming the first seed missing.
    """
    from minari.dataset.minari_storage import MinariStorage

    folders = _datasets_in(source)
    if len(folders) < 2:
        return
    have = {_seed_of(MinariStorage.read(folder), source) for folder in folders}
    missing = [s for s in seeds if s not in have]
    if missing:
        raise UserError(f"{source}: no dataset exported with seed {missing[0]} (seeds there: "
                        f"{sorted(s for s in have if s is not None)})")


def _exported(storage: Any, source: str) -> dict[str, Any] | None:
    """The ``grail_bench`` metadata of a dataset grail-bench exported (None for datasets recorded elsewhere).

    Raises:
        UserError: When it is there but not a JSON object.
    """
    raw = storage.metadata.get(METADATA)
    if raw is None:
        return None
    try:
        meta = json.loads(raw)
    except (TypeError, ValueError):
        meta = None
    if not isinstance(meta, dict):
        raise UserError(f"{source}: the dataset's {METADATA} metadata is not a JSON object")
    return meta


def _seed_of(storage: Any, source: str) -> int | None:
    seed = (_exported(storage, source) or {}).get("seed")
    return seed if isinstance(seed, int) and not isinstance(seed, bool) else None


_ABSENT = object()


def _origin_fields(task: GRTask, meta: dict[str, Any]) -> list[tuple[str, Any, Any]]:
    """``(field, the dataset's, the task's)`` for every field an exported dataset records of its task, in the
    order they are checked: task ID, regime, regime parameters, env parameters, goals."""
    out: list[tuple[str, Any, Any]] = [("task", meta.get("task", _ABSENT), task.id),
                                       ("regime", meta.get("regime", _ABSENT), task.regime)]
    theirs = meta.get("params")
    theirs = stored_params(task.spec, theirs, meta.get("regime")) if isinstance(theirs, dict) else {}
    for name in sorted({*theirs, *task.params}):
        out.append((f"params.{name}", theirs.get(name, _ABSENT), task.params.get(name, _ABSENT)))
    theirs = meta.get("env") if isinstance(meta.get("env"), dict) else {}
    for name in sorted({*theirs, *task.env_params}):
        out.append((f"env.{name}", theirs.get(name, _ABSENT), task.env_params.get(name, _ABSENT)))
    out.append(("goals", meta.get("goals", _ABSENT), [list(g) for g in task.goals]))
    return out


def _show(value: Any) -> str:
    return "absent" if value is _ABSENT else json.dumps(value, default=str)


def _check_origin(task: GRTask, storage: Any, source: str) -> None:
    """Refuse a dataset grail-bench exported from another task (or the same one with other parameters).

    Raises:
        UserError: Naming the first field that differs.
    """
    meta = _exported(storage, source)
    if meta is None:
        return
    for name, theirs, ours in _origin_fields(task, meta):
        if theirs is _ABSENT or ours is _ABSENT or freeze(theirs) != freeze(ours):
            raise UserError(f"{source}: the dataset was exported from another task than {task.id}: its {name} = "
                            f"{_show(theirs)}, not {_show(ours)}")


def _check_space(what: str, theirs: Any, ours: Any, source: str) -> None:
    if theirs != ours:
        raise UserError(_one_line(f"{source}: the dataset's {what} space {theirs} is not the task's {ours}"))


def _one_line(text: str) -> str:
    return " ".join(text.split())


def load_demos(task: GRTask, source: str, seed: int | None) -> Loaded:
    """The demonstrations a Minari dataset gives ``task`` for ``seed`` (see the module docstring).

    With several datasets, the one exported with ``seed`` is read (``None``: the lowest seed's); every one
    of them must have been exported from this task.

    Raises:
        UserError: For a source that holds no dataset, no dataset of this seed among several, a dataset
            exported from another task, spaces other than the task's, observations or actions outside them,
            or episodes without goal labels, of unknown goals or without both splits.
    """
    minari_module()
    from minari.dataset.minari_storage import MinariStorage

    folders = _datasets_in(source)
    try:
        storages = [MinariStorage.read(folder) for folder in folders]
    except Exception as exc:  # noqa: BLE001 - any unreadable dataset is bad input, said in one line
        raise UserError(_one_line(f"{source}: cannot read the Minari dataset ({type(exc).__name__}: {exc})")) from None
    for storage in storages:
        _check_origin(task, storage, source)
    if len(storages) > 1:
        seeds = [_seed_of(s, source) for s in storages]
        wanted = min((s for s in seeds if s is not None), default=None) if seed is None else seed
        storages = [s for s, own in zip(storages, seeds) if own == wanted]
        if len(storages) != 1:
            raise UserError(f"{source}: {len(folders)} datasets, and {len(storages)} exported with seed {seed}; "
                            "name one dataset, or a folder with one per seed")
    storage = storages[0]
    env = task.make_env()
    try:
        spaces = env.observation_space, env.action_space
    finally:
        env.close()
    _check_space("observation", storage.observation_space, spaces[0], source)
    _check_space("action", storage.action_space, spaces[1], source)
    indices = range(storage.total_episodes)
    try:
        labels = list(storage.get_episode_metadata(indices))
        episodes = list(storage.get_episodes(indices))
    except Exception as exc:  # noqa: BLE001 - a corrupt file is bad input too
        raise UserError(_one_line(f"{source}: cannot read the dataset's episodes ({type(exc).__name__}: {exc})")) from None
    return _labelled(task, source, labels, episodes, spaces, _seed_of(storage, source))


def _check_episode(source: str, index: int, obs: np.ndarray, acts: np.ndarray, spaces: tuple[Any, Any]) -> None:
    """Refuse an episode whose observations or actions are not of the task env's spaces.

    Raises:
        UserError: Naming the episode and the first offending value.
    """
    from grail_bench.core.spaces import check_within

    where = f"{source}: episode {index}"
    obs_space, act_space = spaces
    if obs.ndim < 1 or obs.shape[1:] != tuple(obs_space.shape or ()):
        raise UserError(f"{where}: observations of shape {obs.shape[1:]}, the task's are {obs_space.shape}")
    if acts.ndim < 1 or acts.shape[1:] != tuple(act_space.shape or ()):
        raise UserError(f"{where}: actions of shape {acts.shape[1:]}, the task's are {act_space.shape}")
    if len(obs) != len(acts) + 1:
        raise UserError(f"{where}: {len(obs)} observations for {len(acts)} actions (expected one more)")
    try:
        check_within(obs, obs_space, "observations")
        check_within(acts, act_space, "actions")
    except UserError as exc:
        raise UserError(_one_line(f"{where}: {exc}")) from None


def _labelled(task: GRTask, source: str, labels: list[dict], episodes: list[dict], spaces: tuple[Any, Any],
              seed: int | None) -> Loaded:
    from grail_bench.core.trajectory import Trajectory

    goals = {tuple(float(c) for c in g): g for g in task.goals}
    parts: dict[Goal, dict[str, list[Any]]] = {g: {"train": [], "test": []} for g in task.goals}
    digest = hashlib.sha256()
    for i, (label, episode) in enumerate(zip(labels, episodes, strict=True)):
        if "goal" not in label or label.get("split") not in SPLITS:
            raise UserError(f"{source}: episode {i} has no goal label and split (train or test) in its metadata")
        key = tuple(float(c) for c in np.asarray(label["goal"]).ravel())
        if key not in goals:
            raise UserError(f"{source}: episode {i} is labelled with goal {list(key)}, not a goal of {task.id} "
                            f"({[list(g) for g in task.goals]})")
        obs, acts = np.asarray(episode["observations"]), np.asarray(episode["actions"])
        _check_episode(source, i, obs, acts, spaces)
        success = np.asarray((episode.get("infos") or {}).get("is_success", np.zeros(len(acts) + 1, bool)))
        infos = np.array([{"is_success": bool(s)} for s in success[1:]], dtype=object)
        parts[goals[key]][label["split"]].append(Trajectory(obs=obs, acts=acts, infos=infos, terminal=True))
        for array in (obs, acts):
            digest.update(np.ascontiguousarray(array).tobytes())
        digest.update(json.dumps([list(key), label["split"]]).encode())
    n_train = {len(p["train"]) for p in parts.values()}
    if any(not p["train"] or not p["test"] for p in parts.values()) or len(n_train) != 1:
        counts = {str(list(g)): (len(p["train"]), len(p["test"])) for g, p in parts.items()}
        raise UserError(f"{source}: every goal of {task.id} needs training and test episodes, the same number of "
                        f"training ones each; (train, test) per goal: {counts}")
    demos = {g: [*p["train"], *p["test"]] for g, p in parts.items()}
    return Loaded(demos, n_train.pop(), min(len(d) for d in demos.values()), digest.hexdigest()[:16], seed)
