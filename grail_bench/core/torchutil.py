"""Small torch and imitation helpers shared by the learning recognizers."""

from __future__ import annotations

import contextlib
import os
from typing import Any, Iterator

import torch
from imitation.util.logger import HierarchicalLogger
from stable_baselines3.common.logger import KVWriter, Logger

from grail_bench.core.paths import cache_dir

_INDUCTOR_CACHE = "TORCHINDUCTOR_CACHE_DIR"


class _Recorder(KVWriter):
    """Keeps every logged value in memory, by key, in the order it was dumped."""

    def __init__(self) -> None:
        self.values: dict[str, list[float]] = {}

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, Any], step: int = 0) -> None:
        for key, value in key_values.items():
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                self.values.setdefault(key, []).append(float(value))

    def close(self) -> None:
        pass


def recording_logger() -> tuple[HierarchicalLogger, dict[str, list[float]]]:
    """An imitation logger that writes no file, and the values it was given (by key, one per dump)."""
    recorder = _Recorder()
    return HierarchicalLogger(Logger(folder=None, output_formats=[recorder]), format_strs=[]), recorder.values


@contextlib.contextmanager
def single_thread() -> Iterator[None]:
    """Build and train small networks on one thread (faster at these sizes), then restore.

    For the duration, torch's compiler cache (a folder torch creates when an
    optimizer is first built) goes to the suite's cache rather than ``$TMPDIR``,
    unless the user chose a place for it.
    """
    before = torch.get_num_threads()
    chosen = os.environ.get(_INDUCTOR_CACHE)
    torch.set_num_threads(1)
    if chosen is None:
        os.environ[_INDUCTOR_CACHE] = str(cache_dir() / "torchinductor")
    try:
        yield
    finally:
        torch.set_num_threads(before)
        if chosen is None:
            os.environ.pop(_INDUCTOR_CACHE, None)


@contextlib.contextmanager
def unchecked_distributions() -> Iterator[None]:
    """Skip torch.distributions' argument checks (a debugging aid) while training, then restore.

    The policies build a distribution from logits that are finite by
    construction; the checks cost about a tenth of a PPO update at these sizes
    and change no number.
    """
    before = torch.distributions.Distribution._validate_args
    torch.distributions.Distribution.set_default_validate_args(False)
    try:
        yield
    finally:
        torch.distributions.Distribution.set_default_validate_args(before)


@contextlib.contextmanager
def scratch_logger() -> Iterator[HierarchicalLogger]:
    """A silent logger for imitation's adversarial trainers.

    Their ``accumulate_means`` insists on a folder; it lives in a temporary
    directory removed on exit, so nothing is left in the working directory
    or ``$TMPDIR``.
    """
    import tempfile

    with tempfile.TemporaryDirectory(prefix="grail-bench-") as folder:
        yield HierarchicalLogger(Logger(folder=folder, output_formats=[]), format_strs=[])
