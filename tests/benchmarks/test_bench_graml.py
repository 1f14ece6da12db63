"""GRAML's speed beside BC-GRAIL's (``make bench``), on the task and observation of ``test_speed.py``.

Run alone: ``.venv/bin/python -m pytest tests/benchmarks/test_bench_graml.py --benchmark-only``. Fits are of all 6
goals at each recognizer's default budget (GRAML learns one metric for every goal; BC-GRAIL one policy per goal).
GRAML embeds each goal's references once per observed length: ``score`` is the cost when that length was seen
before, ``score_new_length`` when the references are embedded anew.
"""

from __future__ import annotations

import pytest

from grail_bench.recognizers import make_recognizer

from .workload import TASK, TRAIN, thirty_steps


@pytest.fixture(scope="module")
def fitted():
    """Both recognizers fitted once (this also pays torch's one-off imports before any timing)."""
    out = {}
    for name in ("graml", "bc"):
        out[name] = make_recognizer(name)
        out[name].fit(TRAIN, TASK.make_env, seed=0)
    return out


@pytest.mark.parametrize("name", ["graml", "bc"])
def test_fit_6_goals(benchmark, fitted, name):
    benchmark.group = "GRAML vs BC-GRAIL: fit, MiniGrid-Suboptimal-6Goals"
    benchmark.pedantic(make_recognizer(name).fit, args=(TRAIN, TASK.make_env), kwargs={"seed": 0}, rounds=2)


@pytest.mark.parametrize("name", ["graml", "bc"])
def test_score_30_steps_6_goals(benchmark, fitted, name):
    benchmark.group = "GRAML vs BC-GRAIL: score 30 steps, 6 goals"
    assert len(benchmark(fitted[name].score, thirty_steps())) == 6


def test_graml_score_new_length_30_steps_6_goals(benchmark, fitted):
    benchmark.group = "GRAML vs BC-GRAIL: score 30 steps, 6 goals"
    rec = fitted["graml"]
    scores = benchmark.pedantic(rec.score, args=(thirty_steps(),), setup=rec._embedded.clear, rounds=30)
    assert len(scores) == 6
