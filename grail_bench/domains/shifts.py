"""The test-time action-scale shift the continuous-control domains share (``test_action_scale``).

Each step of a test demonstration executes the demonstrator's action multiplied by ``test_action_scale`` and
clipped to the action bounds (below 1 a weaker actuator, above 1 a stronger one, up to the bounds); the
demonstration records the demonstrator's action. Training demonstrations and every env a recognizer builds
keep the scale 1. Plain data and validation: domain modules import this on ``import gymnasium``.
"""

from __future__ import annotations

from typing import Any, Mapping

from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError

#: The shift and the value that means "as in training".
ACTION_SCALE: Mapping[str, Any] = {"test_action_scale": 1.0}
#: Its bound: far beyond the action bounds a scale can still matter for.
ACTION_SCALE_BOUND: Mapping[str, Range] = {"test_action_scale": Range(0.0, 100.0)}


def check_action_scale(test_params: Mapping[str, Any]) -> None:
    """Refuse a ``test_action_scale`` that is no positive number.

    Raises:
        UserError: Naming the value.
    """
    value = test_params.get("test_action_scale", 1.0)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise UserError(f"test_action_scale must be a number > 0, got {value!r}")


def action_scale_overrides(test_params: Mapping[str, Any]) -> dict[str, Any]:
    """The env keyword arguments of the test demonstrations' env: ``action_scale`` when it is shifted."""
    scale = float(test_params.get("test_action_scale", 1.0))
    return {"action_scale": scale} if scale != 1.0 else {}
