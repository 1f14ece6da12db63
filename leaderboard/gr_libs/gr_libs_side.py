"""gr_libs 1.0.3 on one of its own MiniGrid problems, under its own protocol, instance by instance.

Runs in ``leaderboard/gr_libs/.venv`` (gr_libs and its stack; no grail-bench import). It follows
``gr_libs.odgr_executor.run_odgr_problem`` step for step (domain learning, goals adaptation, then every
``I_*`` inference instance of the task in ``gr_libs.problems.consts.PROBLEMS``: train or load the actor,
``generate_observation`` with ``stochastic_amplified_selection``, ``random_subset_with_order`` of
``int(p * T)`` pairs, ``inference_phase``), and records each instance, so the summary can be computed both
as gr_libs computes it (its correctness check and its inference-time average) and correctly.

What it changes, each said in RESULTS.md: the Q-learning budget (``--episodes``, gr_libs' tasks ask for
100 000 episodes per goal), GRAML's LSTM dataset size (``--lstm-samples``, gr_libs' MiniGrid uses 40 000),
and seeding: gr_libs seeds nothing, so every run here seeds ``random``, ``numpy.random``, torch and the
``Random()`` that ``TabularQLearner`` shares through its default argument from the run's seed. As gr_libs'
``all_experiments.py`` does (it runs the executor n times in one folder), every run works in one shared
folder: gr_libs keeps trained agents, datasets and LSTMs in ``./trained_agents`` and ``./gr_cache`` and
reuses whatever is there, so the first run trains and the others only observe and infer again
(``--fresh-per-run`` retrains in every run). Each recognizer's recorded learning time is its first run's.

    .venv/bin/python gr_libs_side.py --recognizer Graql --recognizer ExpertBasedGraml --task L5 --runs 5 \
        --episodes 1000 --lstm-samples 2000 --out gr_libs.json
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import os
import random
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("TQDM_DISABLE", "1")  # tqdm reads it on import; gr_libs' learners draw a bar per goal

import numpy as np
import torch

import gr_libs.environment  # noqa: F401  (registers gr_envs' MiniGrid problems)
from gr_libs.environment._utils.utils import domain_to_env_property
from gr_libs.environment.environment import QLEARNING, LSTMProperties, MinigridProperty
from gr_libs.metrics.metrics import stochastic_amplified_selection
from gr_libs.ml.tabular.tabular_q_learner import TabularQLearner
from gr_libs.ml.utils.format import random_subset_with_order
from gr_libs.problems.consts import PROBLEMS
from gr_libs.recognizer._utils import recognizer_str_to_obj
from gr_libs.recognizer.graml.graml_recognizer import Graml
from gr_libs.recognizer.recognizer import GaAgentTrainerRecognizer, LearningRecognizer
from grlibs_protocol import grlibs_correct, grlibs_summary

DOMAIN = "minigrid"


def seed_everything(seed: int) -> None:
    """Seed every random stream gr_libs draws from (it seeds none itself)."""
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    for default in TabularQLearner.__init__.__defaults__ or ():
        if isinstance(default, random.Random):  # `rand: Random = Random()`, shared by every learner
            default.seed(seed)


def with_budget(task_inputs: dict[str, Any], episodes: int) -> dict[str, Any]:
    """The task's inputs with every Q-learning budget set to ``episodes``."""
    def swap(config: Any) -> Any:
        if isinstance(config, tuple) and len(config) == 2 and config[0] == QLEARNING:
            return (QLEARNING, episodes)
        return config

    out = copy.deepcopy(task_inputs)
    for value in out.values():
        for part in ([value] + [v for v in value.values() if isinstance(v, dict)]):
            if "train_configs" in part:
                part["train_configs"] = [swap(c) for c in part["train_configs"]]
            if "train_config" in part:
                part["train_config"] = swap(part["train_config"])
    return out


def set_lstm_samples(n: int) -> None:
    """GRAML's dataset size on MiniGrid (``MinigridProperty.get_lstm_props``, 40 000 in gr_libs)."""
    props = MinigridProperty.get_lstm_props(MinigridProperty("MiniGrid-SimpleCrossingS13N4"))
    patched = LSTMProperties(batch_size=props.batch_size, input_size=props.input_size,
                             hidden_size=props.hidden_size, num_samples=n)
    MinigridProperty.get_lstm_props = lambda self: patched  # type: ignore[method-assign]


def _train_goal(job: tuple[str, str, tuple[int, int], int, int]) -> tuple[list[int], float, float]:
    """Train one goal's Q-table with gr_libs' own ``TabularQLearner`` in ``folder`` (a worker process)."""
    folder, env_name, goal, episodes, seed = job
    os.chdir(folder)
    seed_everything(seed)
    env_property = domain_to_env_property(DOMAIN)(env_name)
    wall, cpu = time.perf_counter(), time.process_time()
    with contextlib.redirect_stdout(io.StringIO()):
        agent = TabularQLearner(domain_name=DOMAIN, problem_name=env_property.goal_to_problem_str(goal),
                                env_prop=env_property, algorithm=QLEARNING, num_timesteps=episodes)
        agent.learn()  # saves trained_agents/minigrid/<problem>/TabularQLearner/ under the folder
    return list(goal), time.perf_counter() - wall, time.process_time() - cpu


def pretrain(folder: str, env_name: str, task: str, episodes: int, seed: int, workers: int) -> list[dict[str, Any]]:
    """Train the Q-table of every goal of the task (those of its goals adaptation and its base) before the runs,
    ``workers`` at a time, where gr_libs would train them one after the other inside the recognizer's first
    phase. The recognizers then find them in the folder and load them, as gr_libs loads any trained agent.
    Each goal's random streams are seeded from ``seed`` and its index."""
    from multiprocessing import get_context

    inputs = PROBLEMS[DOMAIN][env_name][task]
    goals: list[tuple[int, int]] = []
    for value in [inputs["G_0"], inputs.get("base", {}).get("bg", {"goals": []})]:
        goals += [tuple(g) for g in value["goals"] if tuple(g) not in goals]
    jobs = [(folder, env_name, g, episodes, seed * 1000 + i) for i, g in enumerate(goals)]
    with get_context("spawn").Pool(workers) as pool:
        done = pool.map(_train_goal, jobs, chunksize=1)
    return [{"goal": g, "wall_seconds": w, "cpu_seconds": c} for g, w, c in done]


def run_once(recognizer_name: str, env_name: str, task: str, episodes: int, seed: int,
             progress: dict[str, str]) -> dict[str, Any]:
    """One run of ``run_odgr_problem``'s loop, in the current folder; every instance recorded. ``progress["phase"]``
    names the task input being processed (``base``, ``G_0``, ``I_*``), so a failure can say where it happened."""
    seed_everything(seed)
    recognizer_type = recognizer_str_to_obj(recognizer_name)
    task_inputs = with_budget(PROBLEMS[DOMAIN][env_name][task], episodes)
    recognizer = recognizer_type(domain_name=DOMAIN, env_name=env_name, collect_statistics=False)
    env_property = domain_to_env_property(DOMAIN)(env_name)
    dlp_time, ga_times, instances, goals = 0.0, [], [], []
    same_model = []
    for key, value in task_inputs.items():
        progress["phase"] = key
        if key == "base":
            if issubclass(recognizer_type, LearningRecognizer):
                start = time.perf_counter()
                recognizer.domain_learning_phase(value)
                dlp_time = time.perf_counter() - start
        elif key.startswith("G_"):
            start = time.perf_counter()
            kwargs: dict[str, Any] = {"dynamic_goals": value["goals"]}
            if issubclass(recognizer_type, GaAgentTrainerRecognizer):
                kwargs["dynamic_train_configs"] = value["train_configs"]
            recognizer.goals_adaptation_phase(**kwargs)
            ga_times.append(time.perf_counter() - start)
            goals = [list(g) for g in value["goals"]]
        elif key.startswith("I_"):
            goal, train_config = value["goal"], value["train_config"]
            problem_name = env_property.goal_to_problem_str(goal)
            agent = recognizer.rl_agent_type(domain_name=DOMAIN, problem_name=problem_name,
                                             algorithm=train_config[0], num_timesteps=train_config[1],
                                             env_prop=env_property)
            agent.learn()  # loads the model the recognizer trained for this goal: same folder, same name
            if hasattr(recognizer, "agents") and isinstance(recognizer.agents, dict):
                same_model.append(agent.q_table == recognizer.agents[problem_name].q_table)
            base = {"goal": list(goal), "percentage": value["percentage"], "consecutive": bool(value["consecutive"])}
            try:
                sequence = agent.generate_observation(action_selection_method=stochastic_amplified_selection,
                                                      save_fig=False, random_optimalism=True, fig_path=None)
            except (ValueError, KeyError) as exc:
                # The actor normalises Q[:3] by its sum: a state whose Q-values are all 0 (never updated) gives
                # NaN probabilities, an unvisited one a KeyError. gr_libs' executor would stop the run here.
                instances.append({**base, "actor_failed": f"{type(exc).__name__}: {exc}"})
                continue
            if issubclass(recognizer_type, Graml):
                recognizer.dump_plans(true_sequence=sequence, true_goal=goal, percentage=value["percentage"])
            partial = random_subset_with_order(sequence, int(value["percentage"] * len(sequence)),
                                               is_consecutive=value["consecutive"])
            start = time.perf_counter()
            closest = recognizer.inference_phase(partial, goal, value["percentage"])
            seconds = time.perf_counter() - start
            instances.append({
                **base, "actor_failed": None, "T": len(sequence), "k": len(partial), "predicted": closest,
                "correct": closest == str(goal), "grlibs_correct": grlibs_correct(goal, closest),
                "inference_seconds": seconds,
                "reached": tuple(agent.env.unwrapped.agent_pos) == tuple(goal),
            })
    return {
        "seed": seed, "goals": goals, "domain_learning_seconds": dlp_time,
        "goals_adaptation_seconds": sum(ga_times), "instances": instances,
        "actor_is_recognizer_model": all(same_model) if same_model else None,
        "grlibs_reported": grlibs_summary(instances),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recognizer", action="append", required=True, choices=["Graql", "ExpertBasedGraml"],
                        help="repeat for several; they share each run's folder (its trained agents), as in gr_libs")
    parser.add_argument("--env-name", default="MiniGrid-SimpleCrossingS13N4")
    parser.add_argument("--task", default="L5")
    parser.add_argument("--runs", type=int, default=3, help="runs with seeds 0..N-1")
    parser.add_argument("--episodes", type=int, default=100_000, help="Q-learning episodes per goal")
    parser.add_argument("--lstm-samples", type=int, default=None, help="GRAML's dataset size (gr_libs: 40000)")
    parser.add_argument("--fresh-per-run", action="store_true",
                        help="train everything anew in every run (default: as gr_libs' all_experiments.py, every "
                             "run shares one folder, so the first run trains and the others reuse its models)")
    parser.add_argument("--workers", type=int, default=2, help="processes training the Q-tables")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    if args.env_name not in PROBLEMS[DOMAIN] or args.task not in PROBLEMS[DOMAIN][args.env_name]:
        sys.exit(f"error: {args.env_name} {args.task} is not a gr_libs MiniGrid problem")
    if args.lstm_samples is not None:
        set_lstm_samples(args.lstm_samples)
    torch.set_num_threads(1)
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name in args.recognizer}
    training: list[list[dict[str, Any]]] = []
    here = os.getcwd()
    shared = None if args.fresh_per_run else tempfile.TemporaryDirectory(prefix="gr_libs_runs_")
    try:
        for seed in range(args.runs):
            folder = tempfile.TemporaryDirectory(prefix="gr_libs_run_") if shared is None else None
            work = (folder or shared).name
            try:
                if folder is not None or seed == 0:
                    training.append(pretrain(work, args.env_name, args.task, args.episodes, seed, args.workers))
                    print(f"run {seed}: {len(training[-1])} Q-tables trained", flush=True)
                os.chdir(work)  # gr_libs keeps agents, datasets and outputs under the working folder
                for name in args.recognizer:
                    start = time.perf_counter()
                    progress = {"phase": ""}
                    try:
                        with contextlib.redirect_stdout(io.StringIO()):  # gr_libs prints as it trains
                            run = run_once(name, args.env_name, args.task, args.episodes, seed, progress)
                    except (ValueError, KeyError) as exc:  # e.g. NaN action probabilities in GRAML's dataset
                        reason = f"{type(exc).__name__}: {exc}"
                        print(f"{name} run {seed} failed in {progress['phase']}: {reason}", flush=True)
                        runs[name].append({"seed": seed, "failed": reason, "phase": progress["phase"]})
                        continue
                    run["wall_seconds"] = time.perf_counter() - start
                    ok = [i for i in run["instances"] if not i["actor_failed"]]
                    acc = np.mean([i["correct"] for i in ok]) if ok else float("nan")
                    print(f"{name} run {seed}: accuracy {acc:.3f} over {len(ok)} instances "
                          f"({len(run['instances']) - len(ok)} actor failures), {run['wall_seconds']:.0f} s",
                          flush=True)
                    runs[name].append(run)
            finally:
                os.chdir(here)
                if folder is not None:
                    folder.cleanup()
    finally:
        if shared is not None:
            shared.cleanup()
    from importlib.metadata import version
    versions = {name: version(name) for name in
                ("gr_libs", "gr_envs", "minigrid", "gymnasium", "torch", "numpy", "stable_baselines3")}
    args.out.write_text(json.dumps({
        "env_name": args.env_name, "task": args.task, "episodes": args.episodes,
        "lstm_samples": args.lstm_samples, "fresh_per_run": args.fresh_per_run, "versions": versions,
        "training": training, "runs": runs,
    }, indent=1) + "\n")


if __name__ == "__main__":
    main()
