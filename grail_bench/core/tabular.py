"""A deterministic goal env's dynamics as tables over state indices, for tabular learners.

An env that can state its dynamics this way offers ``tabular_dynamics()``;
GRAQL then runs Q-learning on the tables instead of stepping the env, with the
same transitions, rewards and episode ends (and so the same Q-tables, bit for
bit: tested on MiniGrid).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class TabularDynamics:
    """Where each action leads from each state, and which steps reach the goal.

    Attributes:
        next_state: ``(S, A)`` successor state index (:func:`grail_bench.core.spaces.state_index`).
        success: ``(S, A)`` whether the step reaches the goal; the env rewards it and the episode ends there.
        start: The state every episode starts from.
        horizon: Episodes are truncated once this many steps were taken.
        success_reward: The reward for reaching the goal at step ``t`` (1-based); every other step earns 0.
    """

    next_state: np.ndarray
    success: np.ndarray
    start: int
    horizon: int
    success_reward: Callable[[int], float]

    def __post_init__(self) -> None:
        if self.next_state.shape != self.success.shape or self.next_state.ndim != 2:
            raise ValueError(f"next_state {self.next_state.shape} and success {self.success.shape} must be one "
                             "(states, actions) shape")
        if not 0 <= self.start < len(self.next_state) or self.horizon < 1:
            raise ValueError(f"start {self.start} must index a state and horizon {self.horizon} be positive")
