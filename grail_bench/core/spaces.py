"""Flat gymnasium spaces as arrays: membership checks (one call for a whole trajectory), discrete state indices,
and SB3's observation encoding in numpy."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from grail_bench.core.errors import UserError


def check_within(values: np.ndarray, space: Any, what: str) -> None:
    """Raise unless every row of ``values`` (``(T, *space.shape)``) belongs to ``space``.

    ``Discrete`` and ``MultiDiscrete`` need integral values in range; ``Box``
    needs finite values within its bounds. Other spaces are not checked.

    Raises:
        UserError: Naming ``what``, the space and the first offending value.
    """
    arr = np.asarray(values)
    if isinstance(space, (spaces.Discrete, spaces.MultiDiscrete)):
        if arr.dtype.kind not in "iub":
            if arr.dtype.kind != "f":
                raise UserError(f"{what} must be integers in {space}, got dtype {arr.dtype}")
            bad = ~np.isfinite(arr) | (arr != np.round(arr))
            if np.count_nonzero(bad):
                raise UserError(f"{what} must be integers in {space}, got {arr[bad].flat[0]!r}")
        low = np.asarray(space.start)
        high = low + (space.nvec if isinstance(space, spaces.MultiDiscrete) else space.n)
        bad = (arr < low) | (arr >= high)
    elif isinstance(space, spaces.Box):
        if arr.dtype.kind not in "iuf":
            raise UserError(f"{what} must be numbers in {space}, got dtype {arr.dtype}")
        bad = ~np.isfinite(arr) | (arr < space.low) | (arr > space.high)
    else:
        return
    if np.count_nonzero(bad):  # a third of ndarray.any()'s cost on these small arrays; this runs per score
        raise UserError(f"{what} lie outside the env's space {space}: {arr[bad].flat[0]!r} at step "
                        f"{int(np.argwhere(bad)[0][0])}")


def n_states(space: spaces.Discrete | spaces.MultiDiscrete) -> int:
    """How many states a discrete space has."""
    return math.prod(int(n) for n in space.nvec) if isinstance(space, spaces.MultiDiscrete) else int(space.n)


def state_index(obs: np.ndarray, space: spaces.Discrete | spaces.MultiDiscrete) -> np.ndarray:
    """Flat table index of discrete observations, ``(T, ...) -> (T,)``."""
    if isinstance(space, spaces.MultiDiscrete):
        return np.ravel_multi_index(tuple(np.asarray(obs, dtype=np.int64).T), tuple(space.nvec))
    return np.asarray(obs, dtype=np.int64).reshape(-1) - int(space.start)


def all_states(space: spaces.Discrete | spaces.MultiDiscrete) -> np.ndarray:
    """Every state of a discrete space, ``(n_states, ...)``, row ``i`` the state whose :func:`state_index` is ``i``."""
    if isinstance(space, spaces.MultiDiscrete):
        return np.stack(np.unravel_index(np.arange(n_states(space)), tuple(space.nvec)), axis=1)
    return np.arange(n_states(space)) + int(space.start)


def preprocess(obs: np.ndarray, space: spaces.Space) -> np.ndarray:
    """Numpy twin of SB3's ``preprocess_obs`` for flat spaces.

    ``Discrete`` and ``MultiDiscrete`` observations become (concatenated)
    one-hot vectors; ``Box`` observations are flattened floats.
    """
    if isinstance(space, spaces.MultiDiscrete):
        offsets = np.concatenate([[0], np.cumsum(space.nvec)[:-1]])
        out = np.zeros((len(obs), int(space.nvec.sum())), dtype=np.float32)
        out[np.arange(len(obs))[:, None], obs.astype(np.int64) + offsets] = 1.0
        return out
    if isinstance(space, spaces.Discrete):
        out = np.zeros((len(obs), int(space.n)), dtype=np.float32)
        out[np.arange(len(obs)), obs.astype(np.int64).reshape(-1) - int(space.start)] = 1.0
        return out
    if isinstance(space, spaces.Box):
        return obs.reshape(len(obs), -1).astype(np.float32)
    raise TypeError(f"unsupported observation space {space}")
