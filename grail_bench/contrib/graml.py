"""GRAML and GC-GRAML: goal recognition as metric learning over observation sequences (gr_libs' recognizers).

A Siamese LSTM embeds a sequence of observed steps (state-action pairs, or states) into a vector, trained so
that sequences of the same goal lie close and sequences of different goals far apart; a goal is recognised by
how close the observed sequence's embedding lies to the embeddings of that goal's reference sequences.
``graml`` (BG-GRAML) takes each goal's references from its demonstrations; ``gc-graml`` (GC-GRAML) from
rollouts of a goal-conditioned policy, so it can score goals it has no demonstrations of (``set_goals``).

What gr_libs (v1.0.3, ``gr_libs/recognizer/graml`` and ``gr_libs/ml/sequential/_lstm_model.py``) does, and
where this differs:

* Network: one LSTM layer (xavier-initialised weights, zero biases), the embedding its last hidden state;
  the similarity of two sequences ``exp(-||h1 - h2||_1)``, trained with binary cross-entropy against "same
  goal". The same here. gr_libs uses 8 hidden units; the default here is 32 (:attr:`GRAMLConfig.hidden`).
* Pairs (``_gr_dataset.generate_datasets``): a random goal, the second of the same goal with probability
  ``1 / max(K, 6)``, both observed at one fraction drawn from 0.3-1.0, each side independently either
  consecutive (its first steps) or an ordered random subset (``random_subset_with_order``), from fresh
  rollouts of its trained agents. Here both sides come from the training demonstrations (each pair draws
  a demonstration per side), through the same two selections as the benchmark's ``prefix`` and ``subset``
  protocols (``k = max(1, ceil(fraction * T))`` steps of the path up to the goal), at fractions 0.1-1.0 by
  default, since the benchmark observes as little as 10 %. Same-goal pairs are half of all pairs, not
  ``1 / max(K, 6)``: with a budget of a few thousand pairs (gr_libs draws 10 000-40 000) balanced labels
  learn faster, and the rarer positives of gr_libs only matter for its larger goal sets.
* Training: gr_libs uses Adadelta (weight decay 0.1) for 5 epochs with early stopping on a 20 % dev split;
  here Adam for a fixed number of epochs on every pair (the budget is a setting, so no split is held back and
  the same seed always trains the same model).
* Inference (``Graml.inference_phase``): each goal's reference sequences are cut to the observed length
  ``k`` twice, as their first ``k`` steps and as an ordered random subset of ``k`` (gr_libs draws those
  once, at the first inference after the goals are set); a goal's similarity is the mean over its references
  of the larger of the two similarities, and gr_libs returns the most similar goal. Here the score is the log
  of that mean similarity (the same ranking, finite scores), the subsets drawn once per observed length and
  goal from the fit's seed; ``aggregate="min"`` scores minus the smallest distance instead.
* References of BG-GRAML: gr_libs' ``ExpertBasedGraml`` trains an RL agent per goal and keeps one greedy
  rollout of it; here every training demonstration of the goal is a reference.
* GC-GRAML: gr_libs trains a goal-conditioned RL agent and learns the metric from its rollouts (it has no
  demonstrations); its references are 5 rollouts per goal. Here the metric is learnt from the
  demonstrations, as for ``graml`` (the same model, cached once for both), and grail-bench's GC-BC,
  trained on the same demonstrations, is the goal-conditioned policy whose sampled rollouts (``n_rollouts``
  per goal, cut after the goal is reached) are every goal's references, fitted or not.

Inputs per step: the state as SB3 encodes it (one-hot for discrete spaces; ``Box`` states standardised with
the training states' mean and spread), then the action (one-hot for ``Discrete``, raw for ``Box``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from importlib.metadata import version
from typing import Annotated, Any, Callable, Literal, Mapping, Sequence

import numpy as np
import torch
from gymnasium import spaces
from torch import nn
from torch.nn import functional as F
from torch.nn.utils.rnn import pack_padded_sequence, pad_sequence

from grail_bench.core.cache import cached
from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.scaling import scale_of
from grail_bench.core.seeding import goal_rng, goal_words
from grail_bench.core.spaces import preprocess
from grail_bench.core.torchutil import single_thread
from grail_bench.core.trajectory import Demos, EnvFactory, Goal, demos_digest, rollout, until_success
from grail_bench.recognizers.contract import (
    FitReport,
    NotFittedError,
    RecognizerBase,
    checked_settings,
    observed_arrays,
    settings_key,
)
from grail_bench.recognizers.gcbc import GCBCRecognizer

ROLLOUTS = 7  #: the seed stream of a goal's reference rollouts (grail_bench.core.seeding uses 0-2)


def goals_and_spaces(name: str, demos: Demos, env_factory: EnvFactory | None) -> tuple[list[Goal], Any, Any]:
    """The goals of ``demos`` in training order (sorted, not as listed) and the env's observation and action
    spaces, for a recognizer that learns from every goal's demonstrations at once.

    Raises:
        UserError: For fewer than two goals, a goal without demonstrations, or no env factory.
    """
    if len(demos) < 2:
        raise UserError(f"{name}: need demonstrations of at least two goals, got {len(demos)}")
    if env_factory is None:
        raise UserError(f"{name}: needs the env factory, to read the observation and action spaces")
    ordered = sorted(tuple(g) for g in demos)
    empty = [g for g in ordered if not len(demos[g])]
    if empty:
        raise UserError(f"{name}: goal {empty[0]} has no demonstrations")
    env = env_factory(ordered[0])
    try:
        return ordered, env.observation_space, env.action_space
    finally:
        env.close()


def train_cached(model: str, key: Mapping[str, Any] | None, train: Callable[[], tuple[dict[str, Any], dict[str, Any]]]
                 ) -> tuple[dict[str, Any], dict[str, Any], float, bool]:
    """Run ``train`` (one thread) or take its result from the model cache under ``key`` (None: no cache).

    Returns:
        The state dict, the extra record, the training seconds and whether the entry was reused.
    """
    with single_thread():
        if key is None:
            start = time.perf_counter()
            state, extra = train()
            return state, extra, time.perf_counter() - start, False
        entry = cached(model, dict(key), train)
        return entry.state, entry.extra, entry.seconds, entry.reused


@dataclass(frozen=True)
class GRAMLConfig:
    """GRAML's settings (they key stored results and the cached metric model).

    The default budget (1000 pairs, 5 epochs) trains the metric of a MiniGrid task in 3-15 s on 2 busy cores
    (2-goal to 6-goal suboptimal tasks, whose demonstrations are the longest); the loss still falls at its
    end, so larger budgets may recognise better.

    Attributes:
        hidden: LSTM units, the embedding's size (gr_libs: 8).
        n_pairs: Training pairs of sub-sequences drawn from the demonstrations (gr_libs: 10 000-40 000).
        n_epochs: Passes over the pairs.
        batch_size: Pairs per gradient step (gr_libs: 16-32).
        learning_rate: Adam's step size.
        fractions: Observed fractions the training pairs are drawn at (gr_libs: 0.3-1.0).
        inputs: ``"states+actions"`` (gr_libs') or ``"states"``: what each step of a sequence holds.
        aggregate: How a goal's reference similarities make its score: ``"mean"`` (gr_libs': the log of the
            mean similarity) or ``"min"`` (minus the smallest distance). Scoring only: the trained model is
            shared across its values.
    """

    hidden: Annotated[int, Range(1, 4096)] = 32
    n_pairs: Annotated[int, Range(1, 10_000_000)] = 1000
    n_epochs: Annotated[int, Range(1, 100_000)] = 5
    batch_size: Annotated[int, Range(1, 1_000_000)] = 32
    learning_rate: float = 1e-2
    fractions: tuple[float, ...] = (0.1, 0.3, 0.5, 0.7, 1.0)
    inputs: Literal["states+actions", "states"] = "states+actions"
    aggregate: Literal["mean", "min"] = field(default="mean", metadata={"scoring": True})

    def __post_init__(self) -> None:
        if min(self.hidden, self.n_pairs, self.n_epochs, self.batch_size) < 1:
            raise UserError("hidden, n_pairs, n_epochs and batch_size must be positive")
        if not (math.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise UserError(f"learning_rate must be a positive number, got {self.learning_rate}")
        if not self.fractions or not all(0 < f <= 1 for f in self.fractions):
            raise UserError(f"fractions must be fractions in (0, 1], got {list(self.fractions)}")


@dataclass(frozen=True)
class GCGRAMLConfig(GRAMLConfig):
    """GC-GRAML's settings: GRAML's, and those of its goal-conditioned policy and references.

    Attributes:
        gc_batches: Gradient steps of the GC-BC policy (its ``n_batches``).
        n_rollouts: Sampled rollouts of the policy per goal, the goal's references (gr_libs: 5).
    """

    gc_batches: Annotated[int, Range(1, 10_000_000)] = 1000
    n_rollouts: Annotated[int, Range(1, 100_000)] = 5

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.gc_batches < 1 or self.n_rollouts < 1:
            raise UserError("gc_batches and n_rollouts must be positive")


class StepEncoder:
    """Turns a sequence's states (and actions) into the LSTM's per-step features.

    Args:
        observation_space: The domain env's observation space.
        action_space: Its action space.
        with_actions: Whether each step holds the action too.
        states: Training states, whose mean and spread standardise ``Box`` states.
    """

    def __init__(self, observation_space: spaces.Space, action_space: spaces.Space, with_actions: bool,
                 states: np.ndarray) -> None:
        self.observation_space, self.action_space, self.with_actions = observation_space, action_space, with_actions
        self.mean, self.scale = np.zeros(1, np.float32), np.ones(1, np.float32)
        if isinstance(observation_space, spaces.Box):
            flat = preprocess(np.asarray(states), observation_space)
            self.mean, self.scale = flat.mean(axis=0), scale_of(flat).astype(np.float32)

    def encode(self, states: np.ndarray, acts: np.ndarray) -> np.ndarray:
        """``(T, F)`` float32 features of ``T`` states and the actions taken in them."""
        parts = [preprocess(np.asarray(states), self.observation_space)]
        if isinstance(self.observation_space, spaces.Box):
            parts[0] = (parts[0] - self.mean) / self.scale
        if self.with_actions:
            acts = np.asarray(acts)
            if isinstance(self.action_space, spaces.Discrete):
                parts.append(preprocess(acts, self.action_space))
            else:
                parts.append(acts.reshape(len(acts), -1).astype(np.float32))
        return np.concatenate(parts, axis=1).astype(np.float32)

    @property
    def size(self) -> int:
        """Features per step."""
        sample = (self.observation_space.sample()[None], self.action_space.sample()[None])
        return self.encode(*sample).shape[1]


class SiameseLSTM(nn.Module):
    """gr_libs' ``LstmObservations``: one LSTM layer whose last hidden state embeds a sequence."""

    def __init__(self, input_size: int, hidden: int) -> None:
        super().__init__()
        self.lstm = nn.LSTM(input_size=input_size, hidden_size=hidden, batch_first=True)
        for name, param in self.lstm.named_parameters():
            if "weight" in name:
                nn.init.xavier_uniform_(param)
            else:
                nn.init.zeros_(param)

    def embed(self, sequences: Sequence[torch.Tensor]) -> torch.Tensor:
        """``(B, hidden)`` embeddings of ``B`` sequences of ``(T_i, F)`` features (lengths may differ)."""
        lengths = torch.tensor([len(s) for s in sequences])
        packed = pack_padded_sequence(pad_sequence(list(sequences), batch_first=True), lengths, batch_first=True,
                                      enforce_sorted=False)
        _, (h, _) = self.lstm(packed)
        return h[-1]


def similarity(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """gr_libs' similarity of embeddings: ``exp(-L1 distance)``, along the last axis."""
    return torch.exp(-torch.sum(torch.abs(a - b), dim=-1))


def observed_steps(length: int, fraction: float) -> int:
    """Steps a protocol observes of a path of ``length`` at ``fraction``: ``max(1, ceil(fraction * length))``."""
    return max(1, min(length, math.ceil(round(fraction * length, 9))))  # 0.3 * 10 is 3.0000000000000004


def selection(length: int, k: int, consecutive: bool, rng: np.random.Generator) -> np.ndarray:
    """Indices of ``k`` of ``length`` steps: the first ``k``, or an ordered random subset (gr_libs' two)."""
    k = min(k, length)
    if consecutive:
        return np.arange(k)
    return np.sort(rng.choice(length, size=k, replace=False))


def train_metric(model: SiameseLSTM, sequences: Sequence[Sequence[np.ndarray]], config: GRAMLConfig,
                 seed: int) -> list[float]:
    """Train ``model`` on pairs of sub-sequences of ``sequences[goal][demo]`` (see the module docstring).

    Build ``model`` after ``torch.manual_seed(seed)``: its initial weights are part of what the seed fixes.

    Returns:
        The mean loss of every epoch.
    """
    rng = np.random.default_rng(seed)
    n_goals = len(sequences)
    firsts, seconds, labels = [], [], []
    for _ in range(config.n_pairs):
        a = int(rng.integers(n_goals))
        same = bool(rng.random() < 0.5)
        b = a if same else int((a + 1 + rng.integers(n_goals - 1)) % n_goals)
        fraction = float(rng.choice(config.fractions))
        for goal, out in ((a, firsts), (b, seconds)):
            seq = sequences[goal][int(rng.integers(len(sequences[goal])))]
            picked = selection(len(seq), observed_steps(len(seq), fraction), bool(rng.random() < 0.5), rng)
            out.append(torch.from_numpy(seq[picked]))
        labels.append(float(same))
    target = torch.tensor(labels)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.learning_rate)
    losses = []
    for _ in range(config.n_epochs):
        order, total = rng.permutation(config.n_pairs), 0.0
        for start in range(0, config.n_pairs, config.batch_size):
            batch = order[start:start + config.batch_size]
            predicted = similarity(model.embed([firsts[i] for i in batch]), model.embed([seconds[i] for i in batch]))
            loss = F.binary_cross_entropy(predicted, target[batch])
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += loss.item() * len(batch)
        losses.append(total / config.n_pairs)
    return losses


class GRAMLRecognizer(RecognizerBase):
    """BG-GRAML: the Siamese LSTM metric, each goal's references its training demonstrations.

    Settings: :class:`GRAMLConfig`. It scores only the goals it was fitted on (it needs a goal's
    demonstrations); see :class:`GCGRAMLRecognizer` for goals without any.

    Args:
        **settings: Fields of :attr:`Config`.

    Raises:
        UserError: For an unknown setting, or a value of the wrong type or out of range.
    """

    name = "graml"
    paper_name = "BG-GRAML"
    Config: type[GRAMLConfig] = GRAMLConfig
    config: GRAMLConfig

    def __init__(self, **settings: Any) -> None:
        self.config = checked_settings(self.Config, settings, self.name)
        self.goals: list[Goal] = []
        self.seed = 0
        self.encoder: StepEncoder | None = None
        self.model: SiameseLSTM | None = None
        self.observation_space: Any = None
        self.action_space: Any = None
        self.curves: dict[str, list[float]] = {}
        self._references: dict[Goal, list[np.ndarray]] = {}  # each goal's encoded reference sequences
        self._embedded: dict[int, dict[Goal, np.ndarray]] = {}  # per observed length: (n, 2, hidden)

    def fit(self, demos: Demos, env_factory: EnvFactory | None = None, *, seed: int = 0,
            cache_key: str | None = None) -> FitReport:
        """Learn the metric from ``demos`` and embed each goal's references (see :class:`grail_bench.Recognizer`).

        With a ``cache_key``, the metric model is cached on disk (``graml`` and ``gc-graml`` share it).

        Raises:
            UserError: For fewer than two goals, a goal without demonstrations, or no env factory.
        """
        report = self._fit_metric(demos, env_factory, seed, cache_key)
        self._set_references({g: [self._encode(until_success(t)) for t in demos[g]] for g in self.goals})
        return report

    def _fit_metric(self, demos: Demos, env_factory: EnvFactory | None, seed: int,
                    cache_key: str | None) -> FitReport:
        ordered, self.observation_space, self.action_space = goals_and_spaces(self.name, demos, env_factory)
        cut = {g: [until_success(t) for t in demos[g]] for g in ordered}
        states = np.concatenate([np.asarray(t.obs[:-1]) for g in ordered for t in cut[g]])
        self.encoder = StepEncoder(self.observation_space, self.action_space,
                                   self.config.inputs == "states+actions", states)
        sequences = [[self._encode(t) for t in cut[g]] for g in ordered]
        metric = GRAMLConfig(**{f.name: getattr(self.config, f.name) for f in dataclasses.fields(GRAMLConfig)})

        def train() -> tuple[dict[str, Any], dict[str, Any]]:
            torch.manual_seed(seed)
            model = SiameseLSTM(self.encoder.size, metric.hidden)
            losses = train_metric(model, sequences, metric, seed)
            return model.state_dict(), {"curves": {"loss": losses}}

        key = None if cache_key is None else {
            "model": "graml-metric", "config": settings_key(metric, models=True), "env": cache_key, "seed": seed,
            "goals": [list(g) for g in ordered], "demos": demos_digest([t for g in ordered for t in demos[g]]),
            "versions": [version("torch")]}
        state, extra, seconds, reused = train_cached("graml-metric", key, train)
        self.model = SiameseLSTM(self.encoder.size, metric.hidden)
        self.model.load_state_dict(state)
        self.model.eval()
        self.goals, self.seed = ordered, seed
        self.curves = dict(extra.get("curves") or {})
        return FitReport(train_seconds=seconds, trained=0 if reused else 1, reused=int(reused))

    def _encode(self, traj: Any) -> np.ndarray:
        """The ``(T, F)`` features of a trajectory's ``T`` actions and the states they were taken in."""
        acts = np.asarray(traj.acts)
        return self.encoder.encode(np.asarray(traj.obs)[: len(acts)], acts)

    def _set_references(self, references: Mapping[Goal, list[np.ndarray]]) -> None:
        self._references = dict(references)
        self._embedded = {}

    def embed(self, states: np.ndarray, acts: np.ndarray) -> np.ndarray:
        """The learnt ``(hidden,)`` embedding of a sequence of ``T`` states and the ``T`` actions taken in them.

        Raises:
            NotFittedError: Before :meth:`fit`.
        """
        if self.model is None:
            raise NotFittedError(f"{self.name}: call fit() before embed()")
        with torch.no_grad():
            return self.model.embed([torch.from_numpy(self.encoder.encode(states, acts))])[0].numpy()

    def _reference_embeddings(self, k: int) -> dict[Goal, np.ndarray]:
        """Each goal's references cut to ``k`` steps, as their first ``k`` and as an ordered random subset,
        embedded: ``{goal: (n, 2, hidden)}`` (drawn once per ``k`` and goal, from the fit's seed)."""
        if k not in self._embedded:
            cuts = []
            for goal in self.goals:
                rng = np.random.default_rng([self.seed, k, *goal_words(goal)])
                for seq in self._references[goal]:
                    cuts += [seq[selection(len(seq), k, consecutive, rng)] for consecutive in (True, False)]
            with torch.no_grad():
                embedded = self.model.embed([torch.from_numpy(c) for c in cuts]).numpy()
            out, start = {}, 0
            for goal in self.goals:
                n = len(self._references[goal])
                out[goal] = embedded[start:start + 2 * n].reshape(n, 2, -1)
                start += 2 * n
            self._embedded[k] = out
        return self._embedded[k]

    def score(self, observed: Any) -> dict[Goal, float]:
        """Each goal's similarity to the observed sequence (see :attr:`GRAMLConfig.aggregate`); higher is likelier.

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For a malformed observation (empty, wrong shapes, values outside the env's spaces).
        """
        if self.model is None:
            raise NotFittedError(f"{self.name}: call fit() before score()")
        states, acts = observed_arrays(observed, self.observation_space, self.action_space)
        with single_thread(), torch.no_grad():
            query = self.model.embed([torch.from_numpy(self.encoder.encode(states, acts))])[0].numpy()
            references = self._reference_embeddings(len(acts))
        scores = {}
        for goal in self.goals:
            distance = np.abs(references[goal] - query).sum(axis=-1, dtype=np.float64).min(axis=1)  # (n,)
            if self.config.aggregate == "mean":  # log of the mean of exp(-distance), computed stably
                closest = distance.min()
                scores[goal] = float(-closest + np.log(np.mean(np.exp(closest - distance))))
            else:
                scores[goal] = -float(distance.min())
        return scores


class GCGRAMLRecognizer(GRAMLRecognizer):
    """GC-GRAML: GRAML's metric, each goal's references sampled rollouts of a goal-conditioned policy (GC-BC).

    Settings: :class:`GCGRAMLConfig`. It scores goals it has no demonstrations of (:meth:`set_goals`).
    """

    name = "gc-graml"
    paper_name = "GC-GRAML"
    Config: type[GCGRAMLConfig] = GCGRAMLConfig
    config: GCGRAMLConfig

    def __init__(self, **settings: Any) -> None:
        super().__init__(**settings)
        self.policy: GCBCRecognizer | None = None
        self._env_factory: EnvFactory | None = None
        self._rollouts: dict[Goal, list[np.ndarray]] = {}

    def fit(self, demos: Demos, env_factory: EnvFactory | None = None, *, seed: int = 0,
            cache_key: str | None = None) -> FitReport:
        """Learn the metric and the goal-conditioned policy from ``demos``; roll the policy out for each goal.

        With a ``cache_key``, both models are cached on disk.
        """
        metric = self._fit_metric(demos, env_factory, seed, cache_key)
        self.policy = GCBCRecognizer(n_batches=self.config.gc_batches)
        policy = self.policy.fit(demos, env_factory, seed=seed, cache_key=cache_key)
        self._env_factory, self._rollouts = env_factory, {}
        self.set_goals(self.goals)
        return FitReport(train_seconds=metric.train_seconds + policy.train_seconds,
                         trained=metric.trained + policy.trained, reused=metric.reused + policy.reused)

    def set_goals(self, goals: Sequence[Goal]) -> None:
        """Score these candidate goals from now on, with or without demonstrations (zero-shot).

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For no goals, or goals of another dimension than the fitted ones.
        """
        if self.policy is None:
            raise NotFittedError(f"{self.name}: call fit() before set_goals()")
        goals = [tuple(g) for g in goals]
        size = len(self.policy.encoder.mean)
        if not goals or any(len(g) != size for g in goals):
            raise UserError(f"{self.name}: candidate goals need {size} coordinates each")
        for goal in goals:
            if goal not in self._rollouts:
                self._rollouts[goal] = self._roll_out(goal)
        self.goals = goals
        self._set_references({g: self._rollouts[g] for g in goals})

    def _roll_out(self, goal: Goal) -> list[np.ndarray]:
        """``n_rollouts`` encoded rollouts of the policy pursuing ``goal``, each cut after the goal is reached.

        Actions are sampled from the policy (discrete: its probabilities; continuous: its mean and std, clipped
        to the action space), so the references vary as demonstrations do.
        """
        rng = goal_rng(self.seed, goal, ROLLOUTS)
        encoder, bank, space = self.policy.encoder, self.policy.bank, self.action_space

        def act(obs: np.ndarray, _step: int) -> Any:
            outputs = bank.outputs_of(encoder.encode(np.asarray(obs)[None], [goal]))
            if isinstance(space, spaces.Discrete):
                probs = outputs[0][0, 0].astype(np.float64)
                return int(rng.choice(len(probs), p=probs / probs.sum())) + int(space.start)
            mean, std = outputs[0][0, 0], outputs[1][0, 0]
            return np.clip(mean + std * rng.standard_normal(mean.shape), space.low, space.high).astype(space.dtype)

        env = self._env_factory(goal)
        try:
            runs = [until_success(rollout(env, act, seed=int(rng.integers(2**31))))
                    for _ in range(self.config.n_rollouts)]
        finally:
            env.close()
        return [self._encode(t) for t in runs]
