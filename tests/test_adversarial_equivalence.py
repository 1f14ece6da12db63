"""GAIL- and AIRL-GRAIL train, from the same seed, what imitation 1.0.1's GAIL and AIRL trained.

The fixtures (``tests/fixtures/adversarial/<case>.npz``, written by ``record.py`` beside them) hold what
imitation 1.0.1's trainers, driven by this suite's loop, trained on gymnasium 0.29.1 and SB3 2.2.1: a SHA-256 of
every generator weight (and, where a tolerance applies, the weights), the generator's values and action
log-probabilities on demonstration states, the discriminator's weights and running statistics, and every
discriminator update's loss and accuracy. MiniGrid's cases must match bit for bit; PointMaze's (MuJoCo physics
and Gaussian policies) to ``1e-6``.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pytest
import torch

import grail_bench
from grail_bench.core.trajectory import flatten
from grail_bench.recognizers import make_recognizer

FIXTURES = Path(__file__).with_name("fixtures") / "adversarial"
MINIGRID = "GRAIL/MiniGrid-Optimal-6Goals-v0"
POINT_MAZE = "GRAIL/PointMaze-Optimal-v0"
#: Case -> (recognizer, task, settings, tolerance). 2048 steps are 4 rounds and 32 discriminator updates: more
#: expert batches than one pass over the demonstrations holds, so the loader reshuffles.
CASES: dict[str, tuple[str, str, dict[str, Any], float]] = {
    "gail-minigrid": ("gail", MINIGRID, {}, 0.0),
    "airl-minigrid": ("airl", MINIGRID, {}, 0.0),
    # A replay buffer that wraps around and rounds that end mid-episode.
    "gail-minigrid-ring": ("gail", MINIGRID, {"gen_replay_buffer_capacity": 700, "n_steps": 48}, 0.0),
    "airl-point-maze": ("airl", POINT_MAZE, {}, 1e-6),
}
TOTAL_TIMESTEPS = 2048
SEED = 3
PROBES = 64  # demonstration states the trained generator is evaluated on


def fingerprint(policy: Any, reward_net: torch.nn.Module, disc: Sequence[Sequence[float]],
                demos: Sequence[Any], full: bool) -> dict[str, np.ndarray]:
    """What a fit is compared by: see the module docstring (``full``: the generator's weights too)."""
    obs, acts = flatten(demos)  # imitation's trajectories or the suite's: the same fields
    with torch.no_grad():
        values, log_prob, _ = policy.evaluate_actions(torch.as_tensor(obs[:PROBES]), torch.as_tensor(acts[:PROBES]))
    weights = {k: v.detach().cpu().numpy() for k, v in policy.state_dict().items()}
    out = {
        "policy_keys": np.array(list(weights)),
        "policy_sha256": np.array([hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()
                                   for v in weights.values()]),
        "values": values.numpy().ravel(),
        "log_prob": log_prob.numpy().ravel(),
        "disc": np.array(disc, dtype=np.float64),
        **{f"reward/{k}": v.detach().cpu().numpy() for k, v in reward_net.state_dict().items()},
    }
    if full:
        out.update({f"policy/{k}": v for k, v in weights.items()})
    return out


def fit(case: str, prepare: Callable[[Any], None] | None = None) -> dict[str, np.ndarray]:
    """Train the case's generator for its task's first goal on one thread; its :func:`fingerprint`.

    Args:
        prepare: Changes the recognizer before it trains (the recorder swaps in the reference trainers).
    """
    name, task_id, settings, tolerance = CASES[case]
    task = grail_bench.make_task(task_id)
    train, _ = task.split(task.generate_demos(seed=0))
    goal = task.goals[0]
    rec = make_recognizer(name, total_timesteps=TOTAL_TIMESTEPS, **settings)
    rec.learn_evidence(train, task.env_factory())
    if prepare is not None:
        prepare(rec)
    seen: dict[str, Any] = {"disc": []}

    class Recording(rec.trainer_cls):
        def __init__(self, **kwargs: Any) -> None:
            super().__init__(**kwargs)
            seen["trainer"] = self

        def train_disc(self) -> Any:
            stats = super().train_disc()
            seen["disc"].append([stats["disc_loss"], stats["disc_acc"]])
            return stats

    rec.trainer_cls = Recording
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        torch.manual_seed(SEED)
        policy, _ = rec.train_policy(goal, train[goal], task.make_env, seed=SEED)
    finally:
        torch.set_num_threads(threads)
    return fingerprint(policy, seen["trainer"]._reward_net, seen["disc"], train[goal], full=tolerance > 0)


@pytest.mark.parametrize("case", list(CASES))
def test_trains_what_imitation_trained(case):
    tolerance = CASES[case][3]
    expected = dict(np.load(FIXTURES / f"{case}.npz"))
    got = fit(case)
    assert sorted(got) == sorted(expected)
    assert list(got["policy_keys"]) == list(expected["policy_keys"])
    for key in sorted(expected):
        if key in ("policy_keys", "policy_sha256"):
            continue
        np.testing.assert_allclose(got[key], expected[key], rtol=0, atol=tolerance, err_msg=f"{case}: {key}")
    if tolerance == 0:
        differ = [k for k, a, b in zip(got["policy_keys"], got["policy_sha256"], expected["policy_sha256"]) if a != b]
        assert not differ, f"{case}: generator weights differ: {differ}"
