"""Speed targets (``make bench``): medians are what the docs' Speed page (docs/speed.md) reports.

Targets (2-core CPU): BC-GRAIL scores a 30-step observation against 6 goals in
<= 30 us and fits a goal in <= 1 s (its numpy loop >= 10x imitation's; 6 goals within 1.5x of a stacked torch
trainer's time); GRAQL fits a goal in <= 10 s and scores
in <= 100 us; GAIL and AIRL train at 3x the generator steps per second of
SB3's torch update with per-step rewards (24.5 s per goal at 40 000 steps). Online mode scores all 30 prefixes of that observation in at
most twice the time of one full score (compare each ``all_prefixes`` median
with its ``score`` one). One Monte Carlo level of a Bayes ceiling takes <= 10 s; ceilings not cached yet compute about
twice as fast on 2 workers.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

import grail_bench
from grail_bench.core.torchutil import single_thread
from grail_bench.harness.ceiling import bayes_ceiling
from grail_bench.recognizers import make_recognizer

from .workload import GOAL, TASK, TEST, TRAIN, thirty_steps


@pytest.fixture(scope="module")
def bc():
    rec = make_recognizer("bc")
    rec.fit(TRAIN, TASK.make_env, seed=0)
    return rec


@pytest.fixture(scope="module")
def graql():
    rec = make_recognizer("graql")
    rec.fit(TRAIN, TASK.make_env, seed=0)
    return rec


def test_bc_score_30_steps_6_goals(benchmark, bc):
    observed = thirty_steps()
    scores = benchmark(bc.score, observed)
    assert len(scores) == 6


def test_bc_score_all_prefixes_30_steps_6_goals(benchmark, bc):
    scores = benchmark(bc.score_prefixes, thirty_steps())
    assert all(s.shape == (30,) for s in scores.values()) and len(scores) == 6


def test_bc_fit_one_goal(benchmark, bc):
    def fit():
        with single_thread():
            return bc.train_policy(GOAL, TRAIN[GOAL], TASK.make_env, seed=1)

    benchmark.pedantic(fit, rounds=5, warmup_rounds=1)


def torch_floor(policies, data, orders, learning_rate: float) -> float:
    """The least a torch trainer of the K goals' actors can cost: one batched model (``torch.bmm`` over the goals,
    2 x 32 tanh, cross-entropy, Adam), each goal stepping through its own batches as BC does (the goals by
    decreasing number of steps, the first k still training)."""
    import torch
    from torch.nn import functional

    from grail_bench.core.spaces import preprocess

    rank = sorted(range(len(orders)), key=lambda i: -len(orders[i]))
    xs = [torch.as_tensor(preprocess(data[i][0], policies[i].observation_space)) for i in rank]
    ys = [torch.as_tensor(data[i][1]).long().reshape(-1) for i in rank]
    offsets = np.cumsum([0] + [len(x) for x in xs[:-1]])
    x_all, y_all = torch.cat(xs), torch.cat(ys)
    steps = [len(orders[i]) for i in rank]
    rows = np.zeros((steps[0], len(rank), orders[0].shape[1]), dtype=np.int64)
    for j, i in enumerate(rank):
        rows[:steps[j], j] = orders[i] + offsets[j]
    rows = torch.as_tensor(rows)
    start = time.perf_counter()
    sizes = [x_all.shape[1], 32, 32, policies[0].action_space.n]
    weights = [torch.nn.Parameter(torch.randn(len(rank), a, b) * 0.1) for a, b in zip(sizes, sizes[1:])]
    biases = [torch.nn.Parameter(torch.zeros(len(rank), 1, b)) for b in sizes[1:]]
    optimizer = torch.optim.Adam(weights + biases, lr=learning_rate)
    t = 0
    for k in range(len(rank), 0, -1):  # the first k goals step until the k-th one's batches run out
        while t < steps[k - 1]:
            idx = rows[t, :k]
            h = x_all[idx]
            for layer, (w, b) in enumerate(zip(weights, biases)):
                h = torch.baddbmm(b[:k], h, w[:k])
                h = torch.tanh(h) if layer < len(weights) - 1 else h
            # Each goal's loss the mean over its own batch.
            loss = functional.cross_entropy(h.reshape(-1, h.shape[-1]), y_all[idx].reshape(-1)) * k
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            t += 1
    return time.perf_counter() - start


def test_bc_fit_6_goals_against_a_torch_floor(benchmark):
    """BC's default fit of all 6 goals of MiniGrid-Optimal-6Goals (100 epochs, batch 8, no cache: every goal
    trains, together) against the torch floor (:func:`torch_floor`: the same steps per goal on the same data,
    its training loop alone), both in this process. Target: ``ratio`` (fit / floor medians) <= 1.5."""
    import torch

    from grail_bench.core import bc_update
    from grail_bench.core.seeding import goal_seed

    task = grail_bench.make_task("GRAIL/MiniGrid-Optimal-6Goals-v0")
    train, _ = task.split(task.generate_demos(seed=0))
    rec = make_recognizer("bc")
    rec.fit(train, task.make_env, seed=0)  # warm-up (imports, evidence)

    policies, data, orders = [], [], []
    for goal in train:
        torch.manual_seed(goal_seed(0, goal))
        data.append(rec.pairs(goal, train[goal]))
        policies.append(rec.new_policy(goal, task.make_env))
        orders.append(bc_update.batch_order(len(data[-1][0]), rec.config.batch_size, rec.config.n_epochs, None))
    with single_thread():
        floor = sorted(torch_floor(policies, data, orders, rec.config.learning_rate) for _ in range(3))[1]

    by_goal = make_recognizer("bc")
    by_goal.stacked = False
    start = time.perf_counter()
    by_goal.fit(train, task.make_env, seed=0)  # once, for the record: the goal-by-goal fit
    by_goal_seconds = time.perf_counter() - start

    benchmark.pedantic(rec.fit, args=(train, task.make_env), kwargs={"seed": 0}, rounds=3, iterations=1)
    fit = benchmark.stats.stats.median
    benchmark.extra_info.update(floor_median=floor, ratio=fit / floor, fit_per_goal=fit / len(train),
                                floor_per_goal=floor / len(train), by_goal_fit=by_goal_seconds,
                                steps=[len(o) for o in orders])


@pytest.mark.parametrize("name", ["bc", "graql"])
def test_fit_diagnostics_6_goals(benchmark, name, bc, graql):
    """Diagnosing one fit of 6 goals (agreement, imitation matrix, 6 greedy rollouts), against that fit's cost:
    the share is stored as extra info (goal: under 5 % of the fit's training seconds)."""
    rec = {"bc": bc, "graql": graql}[name]
    diagnostics = benchmark(rec.diagnose, TRAIN, TEST, TASK.env_factory())
    assert len(diagnostics.goals) == 6
    fit_seconds = rec.fit(TRAIN, TASK.make_env, seed=0).train_seconds  # the training each model cost (cache-free)
    benchmark.extra_info["share_of_fit"] = benchmark.stats.stats.median / fit_seconds


def test_graql_score_30_steps_6_goals(benchmark, graql):
    scores = benchmark(graql.score, thirty_steps())
    assert len(scores) == 6


def test_graql_score_all_prefixes_30_steps_6_goals(benchmark, graql):
    scores = benchmark(graql.score_prefixes, thirty_steps())
    assert all(s.shape == (30,) for s in scores.values()) and len(scores) == 6


def test_graql_fit_one_goal(benchmark):
    rec = make_recognizer("graql")
    benchmark.pedantic(rec.fit, args=({GOAL: TRAIN[GOAL], TASK.goals[1]: []}, TASK.make_env),
                       kwargs={"seed": 0}, rounds=3)  # two goals per round: see the per-goal median / 2


def test_minigrid_env_step(benchmark):
    env = TASK.make_env(GOAL)
    env.reset(seed=0)
    actions = np.random.default_rng(0).integers(0, 3, size=1 << 16)
    state = {"i": 0}

    def step():
        i = state["i"] = (state["i"] + 1) % len(actions)
        _, _, terminated, truncated, _ = env.step(int(actions[i]))
        if terminated or truncated:
            env.reset()

    benchmark(step)


@pytest.mark.parametrize("protocol", ["prefix", "subset"])
def test_bayes_ceiling_monte_carlo_one_level(benchmark, protocol):
    """One Monte Carlo level on the suboptimal 6-goal task (2000 samples, as by default): prefix for the online
    plot's curve, subset for the paper's tables."""
    ceiling = benchmark.pedantic(bayes_ceiling, args=(TASK, protocol, 0.3), kwargs={"samples": 2000}, rounds=3)
    assert ceiling.method == "monte-carlo" and 1 / 6 < ceiling.accuracy <= 1


@pytest.mark.parametrize("workers", [1, 2])
def test_ceilings_not_cached_yet_on_workers(benchmark, tmp_path, monkeypatch, workers):
    """Four Monte Carlo levels of the paper's protocol from an empty cache, as a first leaderboard computes them
    (`--workers`)."""
    from grail_bench.harness.ceiling import ceilings_for
    from grail_bench.harness.executors import make_executor

    cells = [(TASK.id, {}, "subset", level) for level in (0.1, 0.2, 0.3, 0.4)]
    rounds = iter(range(100))

    def empty_cache():
        monkeypatch.setenv("GRAIL_BENCH_CACHE", str(tmp_path / str(next(rounds))))

    def compute():
        executor = make_executor(None, workers)
        try:
            return ceilings_for(cells, samples=1000, executor=executor)
        finally:
            executor.close()

    ceilings = benchmark.pedantic(compute, setup=empty_cache, rounds=2)
    assert len(ceilings) == 4


# --- scorers side by side (same policies, same observation) ---------------------------------


@pytest.mark.parametrize("scorer", ["mse", "wasserstein", "kl", "loglik"])
def test_bc_score_by_scorer(benchmark, bc, scorer):
    benchmark.group = "scorer (BC policies, 30 steps, 6 goals)"
    scores = benchmark(bc.score, thirty_steps(), scorer)
    assert len(scores) == 6


@pytest.mark.parametrize("scorer", ["mse", "wasserstein"])
def test_scorer_function_only(benchmark, bc, scorer):
    """The scoring arithmetic alone, on precomputed policy outputs."""
    from grail_bench.recognizers.scoring import get_scorer

    benchmark.group = "scorer arithmetic only"
    output, actions = bc.policy_output(thirty_steps())
    fn = get_scorer(scorer).fn
    assert benchmark(fn, output, actions).shape == (6,)


# --- PandaReach ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def panda():
    task = grail_bench.make_task("GRAIL/PandaReach-Gaussian-0.1-v0", expert="scripted", n_demos=24, n_train=16)
    train, test = task.split(task.generate_demos(seed=0))
    return task, train, test


def test_panda_env_step(benchmark):
    from grail_bench.domains.panda_reach.env import GRPandaReachEnv

    env = GRPandaReachEnv()
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, size=(4096, 3)).astype(np.float32)
    state = {"i": 0}

    def step():
        i = state["i"] = (state["i"] + 1) % len(actions)
        if env.step(actions[i])[3]:
            env.reset()

    benchmark(step)


@pytest.mark.parametrize("name, config", [("bc", {"n_epochs": 5}), ("draco", {"ppo_steps": 1024})])
def test_panda_score_2_percent_4_goals(benchmark, panda, name, config):
    from grail_bench.task.observation import observe

    task, train, test = panda
    rec = make_recognizer(name, **config)
    rec.fit(train, task.make_env, seed=0)
    observed = observe(test[task.goals[0]][0], 0.02)
    benchmark.group = "PandaReach scoring (2 %, 4 goals)"
    assert len(benchmark(rec.score, observed)) == 4


@pytest.mark.parametrize("loop", ["numpy", "torch"])
@pytest.mark.parametrize("domain", ["minigrid", "panda"])
def test_bc_fit_one_goal_by_loop(benchmark, panda, domain, loop):
    """BC's default fit (100 epochs) of one goal through its numpy loop and through the torch loop (imitation
    1.0.1's ``bc.BC`` loop), which train the same model to float32 rounding (tests/test_bc_update.py). PandaReach:
    16 demonstrations per goal (the paper scale's 150 cost ~9x as much either way). Target: the numpy loop >= 10x
    faster."""
    from grail_bench.core.trajectory import flatten, until_success
    from grail_bench.recognizers.bc import train_bc

    task, train = (TASK, TRAIN) if domain == "minigrid" else panda[:2]
    goal, rec = task.goals[0], make_recognizer("bc")
    obs, acts = flatten([until_success(t) for t in train[goal]])
    cfg = {k: getattr(rec.config, k) for k in ("batch_size", "learning_rate", "ent_weight", "n_epochs")}

    def fit():
        with single_thread():
            train_bc(rec.new_policy(goal, task.make_env), obs, acts, numpy=loop == "numpy", **cfg)

    benchmark.group = f"BC fit, one {domain} goal, by loop"
    benchmark.pedantic(fit, rounds=3 if loop == "numpy" else 1, iterations=1)
    benchmark.extra_info["pairs"] = len(obs)


def test_panda_sac_expert_training_one_goal(benchmark):
    from grail_bench.core.rl import learn, make_sac
    from grail_bench.domains.panda_reach.demos import SAC_NET
    from grail_bench.domains.panda_reach.env import GRPandaReachEnv

    env = GRPandaReachEnv()

    def train():
        with single_thread():  # as grail_bench.core.experts.sac_expert trains
            learn(make_sac(env, SAC_NET, seed=0), 15_000)

    benchmark.pedantic(train, rounds=1, iterations=1)


@pytest.mark.parametrize("path", ["actor", "predict"])
def test_sac_expert_action_by_path(benchmark, path):
    """One action of a PandaReach SAC expert (the demonstrators' per-step cost beside pybullet's step): the
    suite's deterministic actor against SB3's ``predict``, which it equals bit for bit (tests/test_experts.py)."""
    from grail_bench.core.experts import deterministic_actor
    from grail_bench.core.rl import empty_policy
    from grail_bench.domains.panda_reach.demos import SAC_NET
    from grail_bench.domains.panda_reach.env import GRPandaReachEnv

    env = GRPandaReachEnv()
    policy = empty_policy("sac", env.observation_space, env.action_space, SAC_NET)
    policy.set_training_mode(False)
    act = deterministic_actor(policy) if path == "actor" else lambda o: policy.predict(o, deterministic=True)[0]
    obs = env.reset(seed=0)[0]
    benchmark.group = "SAC expert action, by path"
    assert benchmark(act, obs).shape == (3,)


@pytest.mark.parametrize("algorithm", ["ppo", "sac"])
def test_draco_fit_one_goal_panda(benchmark, panda, algorithm):
    """DRACO's fit of one PandaReach goal at its default budget per algorithm (docs/guides/budgets.md)."""
    task, train, _ = panda
    rec = make_recognizer("draco", algorithm=algorithm)
    goal = task.goals[0]

    def fit():
        with single_thread():  # as PolicyRecognizer.fit trains
            rec.train_policy(goal, train[goal], task.make_env, 0)

    benchmark.pedantic(fit, rounds=1, iterations=1)
    benchmark.extra_info["steps"] = getattr(rec.config, f"{algorithm}_steps")


@pytest.mark.parametrize("update", ["numpy", "torch"])
@pytest.mark.parametrize("domain", ["minigrid", "maze"])
def test_draco_fit_one_goal_by_update(benchmark, monkeypatch, domain, update):
    """DRACO's fit of one goal at its default budget (150 000 PPO steps): its update in numpy, as it trains,
    against SB3's torch update, on MiniGrid's discrete and PointMaze's continuous actions (env steps per second
    stored as extra info)."""
    from stable_baselines3 import PPO

    from grail_bench.core import rl

    if update == "torch":
        monkeypatch.setattr(rl, "NumpyPPO", lambda *args, gaussian=False, **kwargs: PPO(*args, **kwargs))
    task = TASK if domain == "minigrid" else grail_bench.make_task("GRAIL/PointMaze-Optimal-v0")
    goal = GOAL if domain == "minigrid" else task.goals[0]
    rec = make_recognizer("draco")

    def fit():
        with single_thread():  # as PolicyRecognizer.fit trains
            rec.train_policy(goal, [], task.make_env, 0)

    benchmark.group = f"DRACO fit of one goal ({domain})"
    benchmark.pedantic(fit, rounds=1, iterations=1)
    benchmark.extra_info["env_steps_per_second"] = rec.config.ppo_steps / benchmark.stats.stats.median


def test_point_maze_env_step(benchmark):
    """One PointMaze step (5 MuJoCo steps of 10 ms)."""
    env = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0").make_env((1, 5))
    env.reset(seed=0)
    action = np.array([0.5, 0.5], dtype=np.float32)

    def step():
        if env.step(action)[3]:
            env.reset(seed=0)

    benchmark(step)


def test_point_maze_demonstrations(benchmark):
    """The scripted demonstrator: 10 demonstrations of each of the 5 goals."""
    task = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0")
    benchmark.pedantic(lambda: task.generate_demos(seed=0), rounds=3, iterations=1)


@pytest.mark.parametrize("name", ["gail", "airl"])
def test_adversarial_fit_one_goal_minigrid(benchmark, name):
    """Default budgets (GAIL 20 000, AIRL 40 000 generator steps); targets: GAIL <= 30 s, AIRL <= 60 s per goal.
    Generator steps per second are stored as extra info."""
    rec = make_recognizer(name)
    goal = TASK.goals[0]

    def fit():
        with single_thread():  # as PolicyRecognizer.fit trains
            rec.train_policy(goal, TRAIN[goal], TASK.make_env, 0)

    benchmark.pedantic(fit, rounds=1, iterations=1)
    benchmark.extra_info["generator_steps_per_second"] = rec.config.total_timesteps / benchmark.stats.stats.median


@pytest.mark.parametrize("update", ["numpy", "torch"])
def test_gail_fit_one_goal_point_maze_by_update(benchmark, update):
    """GAIL's default budget (20 000 generator steps) on PointMaze's continuous actions: the generator's update in
    numpy, as it trains, against SB3's torch update."""
    task = grail_bench.make_task("GRAIL/PointMaze-Optimal-v0")
    train, _ = task.split(task.generate_demos(seed=0))
    rec, goal = make_recognizer("gail", update=update), task.goals[0]
    rec.learn_evidence(train, task.env_factory())

    def fit():
        with single_thread():  # as PolicyRecognizer.fit trains
            rec.train_policy(goal, train[goal], task.make_env, 0)

    benchmark.group = "GAIL fit of one goal (PointMaze)"
    benchmark.pedantic(fit, rounds=1, iterations=1)


@pytest.mark.parametrize("kind", ["vectorised", "copies"])
def test_minigrid_8_envs_step(benchmark, kind):
    """One step of 8 copies of a goal's room, as PPO collects rollouts: the numpy-vectorised env against SB3's
    DummyVecEnv over single envs (env steps per second stored as extra info)."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from grail_bench.domains.minigrid.vector import MiniGridVecEnv

    env_fn = lambda: TASK.make_env(GOAL)  # noqa: E731
    venv = MiniGridVecEnv(env_fn(), 8) if kind == "vectorised" else DummyVecEnv([env_fn] * 8)
    venv.reset()
    actions = np.random.default_rng(0).integers(0, 4, size=(1024, 8))
    count = iter(range(10**9))
    benchmark(lambda: venv.step(actions[next(count) % 1024]))
    benchmark.extra_info["env_steps_per_second"] = 8 / benchmark.stats.stats.median


@pytest.mark.parametrize("car", ["ParkingCar", "highway-env"])
def test_parking_env_step(benchmark, car):
    """One parking step (3 highway-env frames) under random actions, reset every 100 steps as in training: the
    env's car and reset against highway-env's own ``Vehicle`` and ``reset`` (same results bit for bit)."""
    pytest.importorskip("highway_env")
    from parking_reference import HighwayEnvsOwn

    from grail_bench.domains.parking.env import GRParkingEnv

    env = (GRParkingEnv if car == "ParkingCar" else HighwayEnvsOwn)((4,))
    actions = np.random.default_rng(0).uniform(-1, 1, size=(4096, 2)).astype(np.float32)
    state = {"i": 0}

    def step():
        i = state["i"] = (state["i"] + 1) % len(actions)
        if i % 100 == 0 or any(env.step(actions[i])[2:4]):
            env.reset(seed=0)

    env.reset(seed=0)
    benchmark.group = "parking env step"
    benchmark(step)


def test_draco_fit_one_goal_parking(benchmark):
    """DRACO's fit of one parking goal at its default budget (150 000 PPO steps, env steps per second stored as
    extra info): where the parking lot's simulator used to make DRACO hours per seed."""
    pytest.importorskip("highway_env")
    task = grail_bench.make_task("GRAIL/Parking-Optimal-v0")
    rec = make_recognizer("draco")

    def fit():
        with single_thread():  # as PolicyRecognizer.fit trains
            rec.train_policy(task.goals[0], [], task.make_env, 0)

    benchmark.pedantic(fit, rounds=1, iterations=1)
    benchmark.extra_info["env_steps_per_second"] = rec.config.ppo_steps / benchmark.stats.stats.median

