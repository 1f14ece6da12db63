"""GRNet: a discriminative sequence model of the goal, a GRU over the observed steps with a softmax over the goals.

In the spirit of GRNet (Chiari et al., "Goal recognition as a deep learning task: the GRNet approach", ICAPS
2023): rather than a model of each goal's behaviour (BC, GAIL, ...) or a learnt metric (GRAML), one network reads
the observed sequence and outputs a posterior over the candidate goals directly. It is trained on what the
benchmark will show it: each training demonstration is observed many times (:attr:`GRNetConfig.draws`), each time
under a protocol drawn from :attr:`GRNetConfig.protocols` (the task's ``prefix`` or ``subset``, through
:func:`grail_bench.task.observation.observe`, so exactly as test demonstrations are observed) at a level drawn
uniformly from ``[min_level, 1]`` and on a channel drawn from :attr:`GRNetConfig.train_channels`, and labelled
with the demonstration's goal; the network is fitted to those labels by cross-entropy.

Network: per observed step, the state as SB3 encodes it (one-hot for discrete spaces, ``Box`` states
standardised with the training states' mean and spread) and the action (one-hot for ``Discrete``, raw for
``Box``), each zeroed when its channel hides it, then two flags saying which are seen; one GRU layer; a linear
layer from its last hidden state to one logit per goal. The score of a goal is its log posterior (a log
softmax), so the scores of a sequence sum to one in probability. The GRU reads a sequence in order, so the
scores of every prefix come from one pass (:meth:`GRNetRecognizer.score_prefixes`, the online mode).

Where it differs from GRNet: GRNet reads the names of observed STRIPS actions (an embedding per action name, an
LSTM with attention) and is trained on plans; here any domain's states and/or actions, a plain GRU (no
attention) trained on the suite's training demonstrations only (no extra plans are generated).
It scores only the goals it was fitted on (its output layer has one unit per goal).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib.metadata import version
from typing import Annotated, Any, Sequence

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F
from torch.nn.utils.rnn import pack_padded_sequence, pad_sequence

from grail_bench.contrib.graml import StepEncoder, goals_and_spaces, train_cached
from grail_bench.core.bounds import Range
from grail_bench.core.errors import UserError
from grail_bench.core.spaces import preprocess
from grail_bench.core.torchutil import single_thread
from grail_bench.core.trajectory import Demos, EnvFactory, Goal, demos_digest, until_success
from grail_bench.recognizers.contract import (
    FitReport,
    NotFittedError,
    RecognizerBase,
    checked_settings,
    observed_arrays,
    settings_key,
)
from grail_bench.task.observation import CHANNELS, get_protocol, observe, observed_channel


@dataclass(frozen=True)
class GRNetConfig:
    """GRNet's settings (they key stored results and the cached model).

    The defaults come from the budget study in ``docs/concepts/recognizers.md`` (GRNet section).

    Attributes:
        hidden: GRU units.
        epochs: Passes over the drawn observations.
        draws: Observations drawn from each training demonstration (each at its own protocol, level and channel).
        batch_size: Observations per gradient step.
        learning_rate: Adam's step size.
        min_level: The smallest observability level drawn (levels are uniform in ``[min_level, 1]``).
        protocols: The observation protocols training observations are drawn under (registered names); the
            default covers every built-in protocol over the path up to the goal, so every card's.
        train_channels: The channels training observations are shown on (``pairs``, ``states``, ``actions``);
            it scores only observations on these.
    """

    hidden: Annotated[int, Range(1, 4096)] = 32
    epochs: Annotated[int, Range(1, 100_000)] = 5
    draws: Annotated[int, Range(1, 100_000)] = 20
    batch_size: Annotated[int, Range(1, 1_000_000)] = 32
    learning_rate: float = 1e-2
    min_level: Annotated[float, Range(0.0, 1.0)] = 0.1
    protocols: tuple[str, ...] = ("prefix", "subset")
    train_channels: tuple[str, ...] = CHANNELS

    def __post_init__(self) -> None:
        if min(self.hidden, self.epochs, self.draws, self.batch_size) < 1:
            raise UserError("hidden, epochs, draws and batch_size must be positive")
        if not (math.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise UserError(f"learning_rate must be a positive number, got {self.learning_rate}")
        if not 0 < self.min_level <= 1:
            raise UserError(f"min_level must be a fraction in (0, 1], got {self.min_level}")
        if not self.protocols:
            raise UserError("protocols must name at least one observation protocol")
        for name in self.protocols:
            get_protocol(name)  # a one-line error for an unknown name
        unknown = [c for c in self.train_channels if c not in CHANNELS]
        if not self.train_channels or unknown:
            raise UserError(f"train_channels must be some of {', '.join(CHANNELS)}, got {list(self.train_channels)}")


class GoalGRU(nn.Module):
    """One GRU layer over a sequence's steps, a linear layer from each hidden state to one logit per goal."""

    def __init__(self, input_size: int, hidden: int, n_goals: int) -> None:
        super().__init__()
        self.gru = nn.GRU(input_size=input_size, hidden_size=hidden, batch_first=True)
        self.head = nn.Linear(hidden, n_goals)

    def forward(self, sequences: Sequence[torch.Tensor]) -> torch.Tensor:
        """``(B, K)`` logits of ``B`` sequences of ``(T_i, F)`` features (lengths may differ), at their last step."""
        lengths = torch.tensor([len(s) for s in sequences])
        packed = pack_padded_sequence(pad_sequence(list(sequences), batch_first=True), lengths, batch_first=True,
                                      enforce_sorted=False)
        _, h = self.gru(packed)
        return self.head(h[-1])

    def every_step(self, sequence: torch.Tensor) -> torch.Tensor:
        """``(T, K)`` logits of one ``(T, F)`` sequence after each of its steps."""
        out, _ = self.gru(sequence[None])
        return self.head(out[0])


class ChannelEncoder:
    """A step's features on any channel: the state and action parts (zeroed where hidden) and two seen flags.

    Args:
        encoder: Encodes states and actions (the actions included).
        state: A valid state, standing in for hidden ones before their part is zeroed.
        action: A valid action, likewise.
    """

    def __init__(self, encoder: StepEncoder, state: np.ndarray, action: np.ndarray) -> None:
        self.encoder, self.state, self.action = encoder, np.asarray(state), np.asarray(action)
        self.state_width = preprocess(self.state[None], encoder.observation_space).shape[1]

    @property
    def size(self) -> int:
        """Features per step."""
        return self.encoder.size + 2

    def encode(self, states: np.ndarray, acts: np.ndarray, channel: str) -> np.ndarray:
        """``(T, F)`` float32 features of ``T`` states and the actions taken in them, as ``channel`` shows them."""
        n = len(acts)
        seen_states, seen_acts = channel != "actions", channel != "states"
        states = np.asarray(states) if seen_states else np.repeat(self.state[None], n, axis=0)
        acts = np.asarray(acts) if seen_acts else np.repeat(self.action[None], n, axis=0)
        out = self.encoder.encode(states.astype(self.state.dtype), acts.astype(self.action.dtype))
        if not seen_states:
            out[:, :self.state_width] = 0.0
        if not seen_acts:
            out[:, self.state_width:] = 0.0
        flags = np.broadcast_to(np.array([seen_states, seen_acts], np.float32), (n, 2))
        return np.concatenate([out, flags], axis=1)


def draw_observations(demos: Sequence[Sequence[Any]], config: GRNetConfig, encoder: ChannelEncoder,
                      rng: np.random.Generator) -> tuple[list[torch.Tensor], torch.Tensor]:
    """Every training observation: ``draws`` per demonstration of ``demos[goal]`` (see the module docstring).

    Returns:
        The encoded observations and their goals' indices.
    """
    sequences, labels = [], []
    for label, trajs in enumerate(demos):
        for traj in trajs:
            for _ in range(config.draws):
                protocol = config.protocols[int(rng.integers(len(config.protocols)))]
                channel = config.train_channels[int(rng.integers(len(config.train_channels)))]
                seen = observe(traj, float(rng.uniform(config.min_level, 1.0)), protocol, rng)
                sequences.append(torch.from_numpy(encoder.encode(seen.obs[:len(seen.acts)], seen.acts, channel)))
                labels.append(label)
    return sequences, torch.tensor(labels)


def train_classifier(model: GoalGRU, sequences: Sequence[torch.Tensor], labels: torch.Tensor, config: GRNetConfig,
                     rng: np.random.Generator) -> list[float]:
    """Fit ``model`` to the goals of ``sequences`` by cross-entropy; the mean loss of every epoch."""
    optimizer = torch.optim.Adam(model.parameters(), lr=config.learning_rate)
    losses = []
    for _ in range(config.epochs):
        order, total = rng.permutation(len(sequences)), 0.0
        for start in range(0, len(sequences), config.batch_size):
            batch = order[start:start + config.batch_size]
            loss = F.cross_entropy(model([sequences[i] for i in batch]), labels[batch])
            optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            optimizer.step()
            total += loss.item() * len(batch)
        losses.append(total / len(sequences))
    return losses


class GRNetRecognizer(RecognizerBase):
    """GRNet: a GRU over the observed steps, a softmax over the goals it was fitted on (see the module docstring).

    Settings: :class:`GRNetConfig`.

    Args:
        **settings: Fields of :class:`GRNetConfig`.

    Raises:
        UserError: For an unknown setting, or a value of the wrong type or out of range.
    """

    name = "grnet"
    paper_name = "GRNet"
    channels = frozenset(CHANNELS)
    config: GRNetConfig

    def __init__(self, **settings: Any) -> None:
        self.config = checked_settings(GRNetConfig, settings, self.name)
        self.goals: list[Goal] = []
        self.model: GoalGRU | None = None
        self.encoder: ChannelEncoder | None = None
        self.observation_space: Any = None
        self.action_space: Any = None
        self.curves: dict[str, list[float]] = {}

    def fit(self, demos: Demos, env_factory: EnvFactory | None = None, *, seed: int = 0,
            cache_key: str | None = None) -> FitReport:
        """Train the network on observations drawn from ``demos`` (see :class:`grail_bench.Recognizer`).

        With a ``cache_key``, the trained network is cached on disk.

        Raises:
            UserError: For fewer than two goals, a goal without demonstrations, or no env factory.
        """
        ordered, self.observation_space, self.action_space = goals_and_spaces(self.name, demos, env_factory)
        trajs = [list(demos[g]) for g in ordered]
        first = trajs[0][0]
        states = np.concatenate([np.asarray(until_success(t).obs[:-1]) for ts in trajs for t in ts])  # to the goal
        self.encoder = ChannelEncoder(StepEncoder(self.observation_space, self.action_space, True, states),
                                      np.asarray(first.obs[0]), np.asarray(first.acts[0]))

        def train() -> tuple[dict[str, Any], dict[str, Any]]:
            rng = np.random.default_rng(seed)
            sequences, labels = draw_observations(trajs, self.config, self.encoder, rng)
            torch.manual_seed(seed)
            model = GoalGRU(self.encoder.size, self.config.hidden, len(ordered))
            losses = train_classifier(model, sequences, labels, self.config, rng)
            return model.state_dict(), {"curves": {"loss": losses}}

        key = None if cache_key is None else {
            "model": "grnet", "config": settings_key(self.config, models=True), "env": cache_key, "seed": seed,
            "goals": [list(g) for g in ordered], "demos": demos_digest([t for ts in trajs for t in ts]),
            "versions": [version("torch")]}
        state, extra, seconds, reused = train_cached("grnet", key, train)
        self.model = GoalGRU(self.encoder.size, self.config.hidden, len(ordered))
        self.model.load_state_dict(state)
        self.model.eval()
        self.goals = ordered
        self.curves = dict(extra.get("curves") or {})
        return FitReport(train_seconds=seconds, trained=0 if reused else 1, reused=int(reused))

    def _features(self, observed: Any) -> torch.Tensor:
        """The observed steps' features, checked against the spaces and the channels trained on."""
        if self.model is None:
            raise NotFittedError(f"{self.name}: call fit() before score()")
        states, acts = observed_arrays(observed, self.observation_space, self.action_space, self.channels)
        channel = observed_channel(observed)
        if channel not in self.config.train_channels:
            raise UserError(f"{self.name} was trained on the {', '.join(self.config.train_channels)} channel(s), "
                            f"not {channel} (its train_channels setting)")
        return torch.from_numpy(self.encoder.encode(states, acts, channel))

    def score(self, observed: Any) -> dict[Goal, float]:
        """Each goal's log posterior given the observed sequence.

        Raises:
            NotFittedError: Before :meth:`fit`.
            UserError: For a malformed observation (empty, wrong shapes, values outside the env's spaces) or one
                on a channel it was not trained on.
        """
        features = self._features(observed)
        with single_thread(), torch.no_grad():
            log_posterior = F.log_softmax(self.model([features]), dim=-1)[0].double().numpy()
        return {goal: float(v) for goal, v in zip(self.goals, log_posterior)}

    def score_prefixes(self, observed: Any, scorer: str | None = None) -> dict[Goal, np.ndarray]:
        """Each goal's log posterior after each observed step, ``{goal: (T,) array}``, from one pass.

        Raises:
            The errors of :meth:`score`; and UserError for a registered scorer (it scores with its own only).
        """
        if scorer is not None:
            raise UserError(f"{self.name} scores with its own posterior only, not {scorer!r}")
        features = self._features(observed)
        with single_thread(), torch.no_grad():
            log_posterior = F.log_softmax(self.model.every_step(features), dim=-1).double().numpy()
        return {goal: log_posterior[:, i].copy() for i, goal in enumerate(self.goals)}
