"""A task's demonstrations exported as Minari datasets (``grail-bench export``).

One dataset per task and seed, ID ``grail-bench/<task name>-seed<s>-v0``
(Minari's ``namespace/name-vN``), with every goal's demonstrations as episodes.
Each episode's metadata records its ``goal`` and ``split`` (``train`` or
``test``); the dataset's metadata records, under ``grail_bench``, the task ID,
regime, parameters, env parameters, goals, default protocol, rounding and
levels, the seed and the grail-bench version (what
:mod:`grail_bench.task.datasets` checks a dataset against when a task reads it).
Its ``env_spec`` and ``eval_env_spec`` are the task's gymnasium spec, so
``dataset.recover_environment()`` rebuilds the GRAIL env.

An export is all or nothing: the output folder is checked before any
demonstration is generated; each dataset is written into a temporary folder
beside its final one (after checking the disk has room for it: HDF5 does not
fail cleanly on a full disk) and renamed when complete, so no half-written
dataset ever sits under a dataset's name; if writing any dataset fails, the
datasets and folders the export created are removed before the error (one
line) is raised.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import json
import multiprocessing
import os
import shutil
import sys
import tempfile
import traceback
import warnings
from contextlib import contextmanager
from importlib.metadata import version
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from grail_bench.core.atomic import WriteError, replace_folder, temporary_folder
from grail_bench.core.errors import UserError
from grail_bench.core.paths import check_writable
from grail_bench.core.seeding import seed_list
from grail_bench.task.datasets import METADATA, minari_module
from grail_bench.task.model import GRTask
from grail_bench.task.registration import make_task

NAMESPACE = "grail-bench"
_NAMESPACE_METADATA = "namespace_metadata.json"


def dataset_id(task: GRTask, seed: int) -> str:
    """``grail-bench/MiniGrid-Biased-seed0-v0``: the exported dataset of a task and seed."""
    name = task.id.removeprefix("GRAIL/").rsplit("-v", 1)[0]
    return f"{NAMESPACE}/{name}-seed{seed}-v0"


def export(task: GRTask, seeds: int | Sequence[int], out: str | Path) -> list[Path]:
    """Write one Minari dataset per seed of ``task``'s demonstrations into ``out``; returns their folders.

    Args:
        task: The task (with its overrides).
        seeds: A count (seeds ``0..n-1``) or the seeds.
        out: The folder the datasets go into (created; relative to the working directory if relative).

    Raises:
        UserError: Before any work, for seeds that are not seeds, an ``out`` that cannot be written, or a
            dataset of the same ID already in ``out``.
    """
    minari = minari_module()
    seeds = list(dict.fromkeys(seed_list(seeds)))
    spec = _spec_of(task)
    out = Path(out).expanduser().absolute()  # Minari resolves a relative $MINARI_DATASETS_PATH wrongly
    idents = [dataset_id(task, seed) for seed in seeds]
    for ident in idents:
        if (out / ident).exists():
            raise UserError(f"{out / ident} exists already; export into another folder or remove it")
    check_writable(out, folder=True)
    for ident in idents:  # what an export killed mid-write (a crash in HDF5) left, never under a dataset's name
        for left in (out / ident).parent.glob(f".{(out / ident).name}.*.tmp"):
            shutil.rmtree(left, ignore_errors=True)
    done: list[Path] = []
    namespace = out / NAMESPACE / _NAMESPACE_METADATA
    had_namespace = namespace.exists()
    try:
        for seed, ident in zip(seeds, idents):
            done.append(_write(minari, task, seed, ident, spec, out / ident))
    except BaseException:
        for path in done:
            shutil.rmtree(path, ignore_errors=True)
        if not had_namespace:
            namespace.unlink(missing_ok=True)
        for path in (out / NAMESPACE, out):  # the folders the export created, if nothing else is in them now
            with contextlib.suppress(OSError):
                path.rmdir()
        raise
    return done


def _estimate(trajectories: Sequence[Any]) -> int:
    """Bytes a dataset of ``trajectories`` takes on disk, generously: its arrays, the per-step rewards and flags,
    and HDF5's per-episode overhead, plus a margin."""
    data = sum(np.asarray(t.obs).nbytes + np.asarray(t.acts).nbytes + 11 * len(t.acts) for t in trajectories)
    return int(1.5 * data) + 16 * 1024 * len(trajectories) + 256 * 1024


def _check_space(need: int, final: Path) -> None:
    """Refuse to write a dataset of ``need`` bytes at ``final`` when its disk has less room (HDF5 does not fail
    cleanly on a full disk)."""
    home = final
    while not home.exists():
        home = home.parent
    free = shutil.disk_usage(home).free
    if free < need:
        raise WriteError(f"no space left on device writing {final} (it needs about {need / 1e6:.1f} MB, "
                         f"{free / 1e6:.1f} MB are free)")


def _write(minari: Any, task: GRTask, seed: int, ident: str, spec: Any, final: Path) -> Path:
    """Write the dataset of one seed: into a temporary folder beside ``final``, moved to ``final`` once whole."""
    train, test = task.split(task.generate_demos(seed))
    labelled = [(goal, split, traj) for goal in task.goals
                for split, part in (("train", train), ("test", test)) for traj in part[goal]]
    _check_space(_estimate([traj for _, _, traj in labelled]), final)

    def fill(root: Path) -> None:
        with _datasets_path(root), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="`author", category=UserWarning)
            dataset = minari.create_dataset_from_buffers(
                ident, [_buffer(traj, i) for i, (_, _, traj) in enumerate(labelled)], env=spec, eval_env=spec,
                algorithm_name=f"grail-bench {task.regime} demonstrator", code_permalink="", author="grail-bench",
                description=f"Demonstrations of {task.id} (seed {seed}) by grail-bench: {task.description}",
                requirements=[f"grail-bench=={version('grail-bench')}"], data_format="hdf5")
        storage = dataset.storage
        storage.update_episode_metadata([{"goal": list(map(float, goal)), "split": split}
                                         for goal, split, _ in labelled])
        storage.update_metadata({METADATA: json.dumps({
            "task": task.id, "regime": task.regime, "params": dict(task.params), "env": dict(task.env_params),
            "goals": [list(map(float, g)) for g in task.goals], "protocol": task.protocol,
            "rounding": task.rounding, "observability": list(task.observability), "n_demos": task.n_demos,
            "n_train": task.n_train, "seed": int(seed), "version": version("grail-bench")}, sort_keys=True)})

    with temporary_folder(final) as root:
        _isolated(lambda: fill(root), final)
        namespace = root / NAMESPACE / _NAMESPACE_METADATA  # Minari's file about the namespace, kept if new
        if namespace.exists() and not (final.parent / _NAMESPACE_METADATA).exists():
            replace_folder(namespace, final.parent / _NAMESPACE_METADATA)
        return replace_folder(root / ident, final)


_FAILED = "grail-bench export failed: "  # how a forked writer reports an error it caught


def _isolated(work: Callable[[], None], final: Path) -> None:
    """Run ``work`` (the HDF5 writes) in a forked process, where the platform forks: on a disk that fills up
    HDF5 can crash the process (a segmentation fault after hundreds of lines of errors). The child's output is
    kept, and its failure, crash included, is one line naming ``final``; the temporary folder it wrote into is
    removed by the caller.

    Raises:
        UserError: What ``work`` raised as bad input, or (:class:`WriteError`) why the dataset was not written.
    """
    if not hasattr(os, "fork"):
        with _hdf5_errors(final):
            work()
        return
    context = multiprocessing.get_context("fork")
    with tempfile.TemporaryFile() as log:
        child = context.Process(target=_child, args=(work, log.fileno(), final))
        child.start()
        child.join()
        if child.exitcode == 0:
            return
        log.seek(0)
        text = log.read().decode("utf-8", errors="replace")
    reported = [line.removeprefix(_FAILED) for line in text.splitlines() if line.startswith(_FAILED)]
    if reported:
        raise UserError(reported[-1])
    if "errno = 28" in text or "No space left" in text:
        raise WriteError(f"no space left on device writing {final}")
    last = next((line.strip() for line in reversed(text.splitlines()) if line.strip()), "no output")
    raise WriteError(f"cannot write {final}: the dataset writer stopped (exit status {child.exitcode}: {last[:200]})")


def _child(work: Callable[[], None], log: int, final: Path) -> None:
    """The forked writer: its output goes to ``log``; an error it can name is one marked line."""
    import faulthandler

    faulthandler.disable()  # a crash is reported by the parent, in one line
    os.dup2(log, 1)
    os.dup2(log, 2)
    sys.stdout = sys.stderr = open(log, "w", closefd=False)  # noqa: SIM115 - the child's output, to its end
    try:
        with _hdf5_errors(final):
            work()
    except UserError as exc:
        os.write(log, f"\n{_FAILED}{' '.join(str(exc).split())}\n".encode())
        os._exit(3)
    except BaseException:  # a bug: its traceback is in the log, the parent says the writer stopped
        traceback.print_exc()
        sys.stderr.flush()
        os._exit(1)
    gc.collect()  # close every HDF5 handle while the process can still report
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


@contextmanager
def _hdf5_errors(final: Path) -> Iterator[None]:
    """HDF5's failure to write (it raises ``RuntimeError`` naming the errno) as one line naming ``final``."""
    try:
        yield
    except RuntimeError as exc:
        text = str(exc)
        if "errno = 28" in text or "No space left" in text:
            raise WriteError(f"no space left on device writing {final}") from None
        if "errno = " not in text:
            raise
        raise WriteError(f"cannot write {final}: {' '.join(text.split())[:200]}") from None


@contextmanager
def _datasets_path(root: Path) -> Iterator[None]:
    """Minari writes under ``$MINARI_DATASETS_PATH``: point it at ``root`` (absolute) for the block."""
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
    """The gymnasium spec that rebuilds ``task``'s env: its registered ID with the parameters it overrides.

    ``demos`` is left out: the env does not need the dataset.
    """
    from gymnasium.envs.registration import spec as gym_spec

    overrides = task.overrides_against(make_task(task.id)).as_dict()
    overrides.pop("demos", None)
    registered = gym_spec(task.id)
    return dataclasses.replace(registered, kwargs={**registered.kwargs, **overrides})
