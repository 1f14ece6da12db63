"""Checks that arrays of states or actions lie in a gymnasium space, vectorised (one call for a whole trajectory)."""

from __future__ import annotations

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
