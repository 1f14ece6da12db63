"""Seed derivation: every random stream of a run is keyed by what it is for, never by position.

A goal's demonstrations and a recognizer's per-goal training seed derive from
``(seed, goal)``, not from the goal's index in a task, so goal (7, 3) gets the
same demonstrations and the same trained model in a 4-goal and a 6-goal task.
The observations of one (seed, level, protocol) cell draw from a stream of
their own (:func:`cell_rng`), so running levels together or one at a time,
fresh or resumed, draws the same observations.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import numbers
import zlib
from collections.abc import Iterable
from typing import Sequence

import numpy as np

from grail_bench.core.errors import UserError

DEMOS, TRAINING, EXPERT = 0, 1, 2  # streams derived from one (seed, goal)
MAX_SEEDS = 10_000  #: most seeds one run takes (the paper uses 10)
MAX_SEED = 2**32 - 1  #: largest seed value: numpy's seed range


def goal_words(goal: Sequence[float]) -> list[int]:
    """Two 32-bit words identifying a goal by its coordinates (7 and 7.0 are the same goal)."""
    text = json.dumps([round(float(c), 9) for c in goal])
    digest = hashlib.sha256(text.encode()).digest()
    return [int.from_bytes(digest[:4], "little"), int.from_bytes(digest[4:8], "little")]


def goal_seed_sequence(seed: int, goal: Sequence[float], stream: int) -> np.random.SeedSequence:
    """The seed sequence of one stream of one goal at one run seed."""
    if int(seed) < 0:
        raise UserError(f"seeds must be non-negative integers, got {seed}")
    return np.random.SeedSequence([int(seed), int(stream), *goal_words(goal)])


def goal_rng(seed: int, goal: Sequence[float], stream: int) -> np.random.Generator:
    """A generator for one stream of one goal (e.g. :data:`DEMOS`)."""
    return np.random.default_rng(goal_seed_sequence(seed, goal, stream))


def goal_seed(seed: int, goal: Sequence[float], stream: int = TRAINING) -> int:
    """A 31-bit integer seed (for torch, SB3 and gymnasium) of one stream of one goal."""
    return int(goal_seed_sequence(seed, goal, stream).generate_state(1)[0] >> 1)


def cell_rng(seed: int, level: float, label: str) -> np.random.Generator:
    """The random stream of one (seed, observability level, protocol label) cell.

    It depends on nothing else, so running levels together or one at a time,
    fresh or resumed, draws the same observations.
    """
    return np.random.default_rng([int(seed), int(round(level * 1_000_000)), zlib.crc32(label.encode())])


def seed_list(seeds: int | Iterable[int]) -> list[int]:
    """``n`` means seeds ``0..n-1``; a sequence is used as given.

    Sizes are checked before anything is built, so a mistyped ``--seeds
    100000000`` is refused at once instead of filling memory: a run takes at
    most :data:`MAX_SEEDS` seeds, each an integer in ``0..``:data:`MAX_SEED`
    (numpy's seed range, which the store's integer column also holds).

    Raises:
        UserError: For no seeds, more than :data:`MAX_SEEDS`, or a seed that is
            not an integer in ``0..MAX_SEED``.
    """
    if isinstance(seeds, bool):
        raise UserError(f"seeds are a count or a list of integers, got {seeds!r}")
    if isinstance(seeds, numbers.Integral):
        n = int(seeds)
        if n < 1:
            raise UserError(f"need at least one seed, got {n}")
        if n > MAX_SEEDS:
            raise UserError(f"at most {MAX_SEEDS:,} seeds per run, got {n:,}")
        return list(range(n))
    if isinstance(seeds, (str, bytes)) or not isinstance(seeds, Iterable):
        raise UserError(f"seeds are a count or a list of integers, got {seeds!r}")
    given = list(itertools.islice(seeds, MAX_SEEDS + 1))  # never more than one past the limit
    if len(given) > MAX_SEEDS:
        raise UserError(f"at most {MAX_SEEDS:,} seeds per run, got more")
    if not given:
        raise UserError("need at least one seed")
    out = []
    for s in given:
        if isinstance(s, bool) or not isinstance(s, numbers.Integral):
            raise UserError(f"seeds must be integers, got {s!r}")
        if not 0 <= int(s) <= MAX_SEED:
            raise UserError(f"seeds must be integers in 0..{MAX_SEED}, got {int(s)}")
        out.append(int(s))
    return out
