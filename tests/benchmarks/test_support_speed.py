"""What knowing where the goals have evidence costs (``make bench``): scoring with ``off_support`` and the
``occupancy`` scorer against plain MSE on the same fitted BC, and the evidence's share of a BC fit.

Run alone: ``.venv/bin/python -m pytest tests/benchmarks/test_support_speed.py --benchmark-only``. Each
``off_support`` variant is the fitted BC with only that setting changed (the same policies and evidence). On
continuous observations both cost a pass over every goal's distinct training states per observed state (one matrix
product, and for the occupancy an exponential of each term), so their share grows with the demonstrations: the
PandaReach groups at the card's scale (150 demonstrations per goal) show it beside the small fixture's.
"""

from __future__ import annotations

import copy
import dataclasses
from typing import Any

import pytest
from grail_bench.core.trajectory import Trajectory

import grail_bench
from grail_bench.recognizers import make_recognizer
from grail_bench.task.observation import observe

from .workload import TASK as MINIGRID
from .workload import TRAIN, thirty_steps

#: (off_support, scorer) pairs, plain MSE first; ``loglik`` is the ``occupancy`` scorer less the occupancy (what the
#: scorer's own arithmetic costs beside MSE's, with no evidence read).
VARIANTS = [("trust", "mse"), ("stay", "mse"), ("uniform", "mse"), ("trust", "occupancy"), ("trust", "loglik")]


def _variant(rec: Any, off_support: str) -> Any:
    """The fitted ``rec`` with only its ``off_support`` setting changed."""
    out = copy.copy(rec)
    out.config = dataclasses.replace(rec.config, off_support=off_support)
    return out


@pytest.fixture(scope="module")
def bc():
    rec = make_recognizer("bc")
    report = rec.fit(TRAIN, MINIGRID.make_env, seed=0)
    return rec, report


@pytest.fixture(scope="module")
def panda():
    task = grail_bench.make_task("GRAIL/PandaReach-Gaussian-0.1-v0", expert="scripted", n_demos=24, n_train=16)
    train, test = task.split(task.generate_demos(seed=0))
    rec = make_recognizer("bc")  # its default budget: the fit the evidence's share is of
    report = rec.fit(train, task.make_env, seed=0)
    return task, train, test, rec, report


@pytest.mark.parametrize("off_support, scorer", VARIANTS, ids=[f"{o}-{s}" for o, s in VARIANTS])
def test_support_score_minigrid_30_steps_6_goals(benchmark, bc, off_support, scorer):
    benchmark.group = "support: BC scoring, MiniGrid, 30 steps, 6 goals"
    rec = _variant(bc[0], off_support)
    assert len(benchmark(rec.score, thirty_steps(), scorer)) == 6


@pytest.mark.parametrize("off_support, scorer", VARIANTS, ids=[f"{o}-{s}" for o, s in VARIANTS])
def test_support_score_minigrid_all_prefixes(benchmark, bc, off_support, scorer):
    benchmark.group = "support: BC online scoring (30 prefixes), MiniGrid, 6 goals"
    rec = _variant(bc[0], off_support)
    assert len(benchmark(rec.score_prefixes, thirty_steps(), scorer)) == 6


@pytest.fixture(scope="module")
def panda_paper_scale():
    """PandaReach at the card's scale (150 training demonstrations per goal): what the evidence costs where a goal
    has hundreds of distinct training states (the policies' quality does not matter here: one epoch)."""
    task = grail_bench.make_task("GRAIL/PandaReach-Gaussian-0.1-v0")
    train, test = task.split(task.generate_demos(seed=0))
    rec = make_recognizer("bc", n_epochs=1)
    rec.fit(train, task.make_env, seed=0)
    return task, test, rec


@pytest.mark.parametrize("off_support, scorer", VARIANTS, ids=[f"{o}-{s}" for o, s in VARIANTS])
@pytest.mark.parametrize("observed", ["2 %", "30 steps"])
def test_support_score_panda_paper_scale(benchmark, panda_paper_scale, observed, off_support, scorer):
    task, test, fitted = panda_paper_scale
    benchmark.group = f"support: BC scoring, PandaReach at the card's scale, {observed}, 4 goals"
    rec = _variant(fitted, off_support)
    traj = test[task.goals[0]][0]
    if observed == "2 %":
        traj = observe(traj, 0.02)
    else:
        traj = Trajectory(obs=traj.obs[:31], acts=traj.acts[:30], infos=None, terminal=False)
    assert len(benchmark(rec.score, traj, scorer)) == 4


@pytest.mark.parametrize("off_support, scorer", VARIANTS, ids=[f"{o}-{s}" for o, s in VARIANTS])
def test_support_score_panda_2_percent_4_goals(benchmark, panda, off_support, scorer):
    task, _, test, fitted, _ = panda
    benchmark.group = "support: BC scoring, PandaReach, 2 %, 4 goals"
    rec = _variant(fitted, off_support)
    observed = observe(test[task.goals[0]][0], 0.02)
    assert len(benchmark(rec.score, observed, scorer)) == 4


@pytest.mark.parametrize("off_support, scorer", VARIANTS, ids=[f"{o}-{s}" for o, s in VARIANTS])
def test_support_score_panda_30_steps_4_goals(benchmark, panda, off_support, scorer):
    task, _, test, fitted, _ = panda
    benchmark.group = "support: BC scoring, PandaReach, 30 steps, 4 goals"
    rec = _variant(fitted, off_support)
    traj = test[task.goals[0]][0]
    observed = Trajectory(obs=traj.obs[:31], acts=traj.acts[:30], infos=None, terminal=False)
    assert len(benchmark(rec.score, observed, scorer)) == 4


@pytest.mark.parametrize("domain", ["minigrid", "panda"])
def test_support_evidence_share_of_a_bc_fit(benchmark, bc, panda, domain):
    """Learning the evidence (supports, radii, occupancy with its leave-one-demonstration-out choice), as every
    fit of a policy recognizer now does; its share of that BC fit's training seconds is stored as extra info."""
    if domain == "minigrid":
        (rec, report), train, make_env = bc, TRAIN, MINIGRID.make_env
    else:
        task, train, _, rec, report = panda
        make_env = task.make_env
    benchmark.group = "support: evidence learnt at fit"
    assert benchmark(rec.learn_evidence, train, make_env) is not None
    benchmark.extra_info["share_of_fit"] = benchmark.stats.stats.median / report.train_seconds
    benchmark.extra_info["fit_seconds"] = report.train_seconds
