"""Small torch helpers shared by the learning recognizers."""

from __future__ import annotations

import contextlib
import os
from typing import Iterator

import torch

from grail_bench.core.paths import cache_dir

_INDUCTOR_CACHE = "TORCHINDUCTOR_CACHE_DIR"


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
