"""Demonstrations as Minari datasets, both ways: a task's demonstrations exported, or a dataset's taken as a task's.

Export (:func:`export`, ``grail-bench export``): one dataset per task and
seed, ID ``grail-bench/<task name>-seed<s>-v0`` (Minari's ``namespace/name-vN``),
with every goal's demonstrations as episodes. Each episode's metadata records
its ``goal`` and ``split`` (``train`` or ``test``); the dataset's metadata
records, under ``grail_bench``, the task ID, regime, parameters, env
parameters, goals, default protocol, rounding and levels, the seed and the grail-bench
version. Its ``env_spec`` and ``eval_env_spec`` are the task's gymnasium spec,
so ``dataset.recover_environment()`` rebuilds the GRAIL env.

Import (:func:`load_demos`, a card's ``demos`` field or ``run --demos``): a
dataset folder, a folder of exported datasets (the one whose seed is the run's
seed is used), or a dataset ID under ``$MINARI_DATASETS_PATH``. Episodes need a
``goal`` in their metadata (every task goal with at least one ``train`` and
one ``test`` episode, the same number of training episodes per goal); spaces
must be the task's. Minari's HDF5 storage holds arrays, JSON and attributes
only: loading unpickles nothing. Minari is imported only here, when a dataset
is read or written (``pip install 'grail-bench[minari]'``, which ``make test``
installs).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator, Sequence

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.trajectory import Demos, Goal

if TYPE_CHECKING:
    from grail_bench.task.model import GRTask

NAMESPACE = "grail-bench"
SPLITS = ("train", "test")


def _minari() -> Any:
    try:
        import minari
    except ImportError:
        raise UserError("Minari datasets need minari: pip install 'grail-bench[minari]'") from None
    return minari


def dataset_id(task: GRTask, seed: int) -> str:
    """``grail-bench/MiniGrid-Biased-seed0-v0``: the exported dataset of a task and seed."""
    name = task.id.removeprefix("GRAIL/").rsplit("-v", 1)[0]
    return f"{NAMESPACE}/{name}-seed{seed}-v0"


@contextmanager
def _datasets_path(root: Path) -> Iterator[None]:
    """Minari writes under ``$MINARI_DATASETS_PATH``: point it at ``root`` for the block."""
    before = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = before


def _buffer(traj: Any, index: int) -> Any:
    from minari.data_collector import EpisodeBuffer

    acts = np.asarray(traj.acts)
    success = [False] + [bool(i.get("is_success")) for i in (traj.infos if traj.infos is not None else [{}] * len(acts))]
    return EpisodeBuffer(id=index, observations=list(np.asarray(traj.obs)), actions=list(acts),
                         rewards=[0.0] * len(acts), terminations=[False] * len(acts),
                         truncations=[False] * (len(acts) - 1) + [True], infos={"is_success": success})


def _spec_of(task: GRTask) -> Any:
    """The gymnasium spec that rebuilds ``task``: its registered ID with the parameters it overrides."""
    from gymnasium.envs.registration import spec as gym_spec

    from grail_bench.task.registration import make_task

    base = make_task(task.id)
    mine = {**task.params, **task.env_params, "n_demos": task.n_demos, "n_train": task.n_train}
    default = {**base.params, **base.env_params, "n_demos": base.n_demos, "n_train": base.n_train}
    registered = gym_spec(task.id)
    return dataclasses.replace(registered, kwargs={**registered.kwargs,
                                                   **{k: v for k, v in mine.items() if default.get(k) != v}})


def export(task: GRTask, seeds: Sequence[int], out: Path) -> list[Path]:
    """Write one Minari dataset per seed of ``task``'s demonstrations into ``out``; returns their folders.

    Raises:
        UserError: If a dataset of that ID already exists in ``out``.
    """
    minari = _minari()
    out = Path(out)
    written = []
    for seed in seeds:
        demos = task.generate_demos(seed)
        train, test = task.split(demos)
        labelled = [(goal, split, traj) for goal in task.goals
                    for split, part in (("train", train), ("test", test)) for traj in part[goal]]
        ident = dataset_id(task, seed)
        if (out / ident).exists():
            raise UserError(f"{out / ident} exists already; export into another folder or remove it")
        spec = _spec_of(task)
        with _datasets_path(out), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="`author", category=UserWarning)
            dataset = minari.create_dataset_from_buffers(
                ident, [_buffer(traj, i) for i, (_, _, traj) in enumerate(labelled)], env=spec, eval_env=spec,
                algorithm_name=f"grail-bench {task.regime} demonstrator", code_permalink="", author="grail-bench",
                description=f"Demonstrations of {task.id} (seed {seed}) by grail-bench: {task.description}",
                requirements=[f"grail-bench=={version('grail-bench')}"], data_format="hdf5")
        storage = dataset.storage
        storage.update_episode_metadata([{"goal": list(map(float, goal)), "split": split}
                                         for goal, split, _ in labelled])
        storage.update_metadata({"grail_bench": json.dumps({
            "task": task.id, "regime": task.regime, "params": dict(task.params), "env": dict(task.env_params),
            "goals": [list(map(float, g)) for g in task.goals], "protocol": task.protocol,
            "rounding": task.rounding, "observability": list(task.observability), "n_demos": task.n_demos,
            "n_train": task.n_train,
            "seed": int(seed), "version": version("grail-bench")}, sort_keys=True)})
        written.append(out / ident)
    return written


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
    _minari()
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
    have = {_seed_of(MinariStorage.read(folder)) for folder in folders}
    missing = [s for s in seeds if s not in have]
    if missing:
        raise UserError(f"{source}: no dataset exported with seed {missing[0]} (seeds there: "
                        f"{sorted(s for s in have if s is not None)})")


def _seed_of(storage: Any) -> int | None:
    raw = storage.metadata.get("grail_bench")
    try:
        return int(json.loads(raw)["seed"]) if raw else None
    except (ValueError, KeyError, TypeError):
        return None


def _check_space(what: str, theirs: Any, ours: Any, source: str) -> None:
    if theirs != ours:
        raise UserError(f"{source}: the dataset's {what} space {theirs} is not the task's {ours}")


def load_demos(task: GRTask, source: str, seed: int | None) -> Loaded:
    """The demonstrations a Minari dataset gives ``task`` for ``seed`` (see the module docstring).

    With several datasets, the one exported with ``seed`` is read (``None``: the lowest seed's).

    Raises:
        UserError: For a source that holds no dataset, no dataset of this seed among several, spaces other
            than the task's, or episodes without goal labels, of unknown goals or without both splits.
    """
    _minari()
    from minari.dataset.minari_storage import MinariStorage

    folders = _datasets_in(source)
    try:
        storages = [MinariStorage.read(folder) for folder in folders]
    except Exception as exc:  # noqa: BLE001 - any unreadable dataset is bad input, said in one line
        raise UserError(f"{source}: cannot read the Minari dataset ({type(exc).__name__}: {exc})") from None
    if len(storages) > 1:
        seeds = [_seed_of(s) for s in storages]
        wanted = min((s for s in seeds if s is not None), default=None) if seed is None else seed
        storages = [s for s, own in zip(storages, seeds) if own == wanted]
        if len(storages) != 1:
            raise UserError(f"{source}: {len(folders)} datasets, and {len(storages)} exported with seed {seed}; "
                            "name one dataset, or a folder with one per seed")
    storage = storages[0]
    env = task.make_env()
    try:
        _check_space("observation", storage.observation_space, env.observation_space, source)
        _check_space("action", storage.action_space, env.action_space, source)
    finally:
        env.close()
    indices = range(storage.total_episodes)
    labels = list(storage.get_episode_metadata(indices))
    episodes = list(storage.get_episodes(indices))
    return _labelled(task, source, labels, episodes, _seed_of(storage))


def _labelled(task: GRTask, source: str, labels: list[dict], episodes: list[dict], seed: int | None) -> Loaded:
    from imitation.data.types import Trajectory

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
