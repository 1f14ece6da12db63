"""Shared fixtures."""

from __future__ import annotations

import numpy as np
import pytest

import grail_bench


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator, as imitation's tests use."""
    return np.random.default_rng(0)


@pytest.fixture(scope="session")
def all_task_ids() -> list[str]:
    return grail_bench.task_ids()
