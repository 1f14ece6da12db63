"""GC-DRACO's fit and score times beside BC-GRAIL's (``make bench``), on MiniGrid's 6 goals.

GC-DRACO trains one agent for every goal, by RL: its fit costs its step budget whatever the number of goals,
so its per-goal time falls as goals are added; BC-GRAIL fits one policy per goal. The GC-DRACO fit here runs
a tenth of its default budget (10 240 of 100 000 PPO steps); env steps per second are stored as extra info, and
the default budget's fit is about ``100 000 / steps_per_second`` seconds. Scoring: a 30-step observation against
the 6 goals, both through the same batched policy bank (GC-DRACO's one agent fed each goal's inputs).
"""

from __future__ import annotations

import pytest

from grail_bench.recognizers import make_recognizer

from .workload import TASK, TRAIN, thirty_steps

GC_DRACO = {"ppo_steps": 10_240}


@pytest.fixture(scope="module")
def fitted():
    out = {}
    for name, settings in (("bc", {}), ("gc-draco", GC_DRACO)):
        out[name] = make_recognizer(name, **settings)
        out[name].fit(TRAIN, TASK.env_factory(), seed=0)
    return out


@pytest.mark.parametrize("name", ["bc", "gc-draco"])
def test_fit_6_goals(benchmark, name):
    """A whole fit of the 6 goals (uncached); seconds per goal stored as extra info."""
    settings = GC_DRACO if name == "gc-draco" else {}

    def fit():
        return make_recognizer(name, **settings).fit(TRAIN, TASK.env_factory(), seed=0)

    report = benchmark.pedantic(fit, rounds=3, iterations=1)
    assert report.trained in (1, 6)
    benchmark.extra_info["seconds_per_goal"] = benchmark.stats.stats.median / len(TASK.goals)
    if name == "gc-draco":
        benchmark.extra_info["steps_per_second"] = GC_DRACO["ppo_steps"] / benchmark.stats.stats.median


@pytest.mark.parametrize("name", ["bc", "gc-draco"])
def test_score_30_steps_6_goals(benchmark, fitted, name):
    scores = benchmark(fitted[name].score, thirty_steps())
    assert len(scores) == 6
