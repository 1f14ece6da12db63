"""Small torch and imitation helpers shared by the learning recognizers."""

from __future__ import annotations

import contextlib
from typing import Iterator

import torch
from imitation.util.logger import HierarchicalLogger
from stable_baselines3.common.logger import Logger


def silent_logger() -> HierarchicalLogger:
    """An imitation logger that writes nothing anywhere (no folders in $TMPDIR)."""
    return HierarchicalLogger(Logger(folder=None, output_formats=[]), format_strs=[])


@contextlib.contextmanager
def single_thread() -> Iterator[None]:
    """Run small-network training on one thread (faster for these sizes), then restore."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


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
