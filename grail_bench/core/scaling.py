"""Per-coordinate scales for standardising inputs: the learners' goal and state encoders, the occupancy's kernel."""

from __future__ import annotations

import numpy as np

#: A coordinate whose float64 spread is at most this share of its magnitude (at least 1) is constant: identical
#: values can have a spread of about 1e-17 rather than 0 once averaged in floating point (three goals at z = 0.1).
CONSTANT = 1e-9


def scale_of(points: np.ndarray) -> np.ndarray:
    """The standard deviation of each coordinate of ``(N, D)`` points, in their dtype, and 1 for a coordinate they
    all share up to rounding (dividing by its spread would blow rounding noise up into the inputs)."""
    points = np.asarray(points)
    spread = points.std(axis=0)
    exact = points.astype(np.float64)
    constant = exact.std(axis=0) <= CONSTANT * np.maximum(1.0, np.abs(exact.mean(axis=0)))
    return np.where(constant, 1.0, spread).astype(spread.dtype)
