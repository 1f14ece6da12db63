"""Goal-agnostic scorers: pure functions from policy outputs to one score per goal.

A recognizer that supports pluggable scoring exposes its goal policies' outputs
on the observed states as a :class:`PolicyOutput` (action probabilities, mean
and std, or Q-values, stacked over goals); a :class:`Scorer` turns them and the
observed actions into one score per goal, higher meaning a better fit.

Built-in scorers: ``mse`` (GRAIL's default), ``wasserstein`` (DRACO's), ``kl``
(GRAQL's), ``loglik`` and ``occupancy`` (the log-likelihood of each observed
state-action pair: the policy's log-probability of the action plus the log of
the goal's smoothed state occupancy). More come from the entry-point group
``grail_bench.scorers``, each pointing at a :class:`Scorer`.

Shapes: ``K`` goals, ``T`` observed steps, ``A`` discrete actions or ``D``
action dimensions.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from grail_bench.core.errors import UserError
from grail_bench.core.registry import Registry

EPS = 1e-8
GROUP = "grail_bench.scorers"
OUTPUT_NAMES = {"probs": "action probabilities", "mean": "mean actions", "std": "action std", "q": "Q-values",
                "occupancy": "state occupancy"}
#: The :class:`PolicyOutput` field behind an output name, where they differ.
_FIELDS = {"occupancy": "log_occupancy"}


@dataclass(frozen=True)
class PolicyOutput:
    """Goal policies evaluated on the observed states; fields a recognizer lacks stay ``None``.

    Attributes:
        probs: ``(K, T, A)`` action probabilities (discrete actions).
        mean: ``(K, T, D)`` mean actions (continuous actions).
        std: ``(K, T, D)`` or ``(K, 1, D)`` action standard deviations.
        q: ``(K, T, A)`` action values.
        log_occupancy: ``(K, T)`` log of each goal's smoothed state occupancy at the observed states, estimated
            from its training demonstrations (exposed as ``"occupancy"``).
    """

    probs: np.ndarray | None = None
    mean: np.ndarray | None = None
    std: np.ndarray | None = None
    q: np.ndarray | None = None
    log_occupancy: np.ndarray | None = None

    def exposes(self) -> frozenset[str]:
        return frozenset(k for k in OUTPUT_NAMES if getattr(self, _FIELDS.get(k, k)) is not None)

    def head(self, k: int) -> PolicyOutput:
        """The outputs on the first ``k`` steps (a ``(K, 1, D)`` std is shared by every step and kept)."""
        def cut(name: str) -> np.ndarray | None:
            a = getattr(self, name)
            return a if a is None or (name == "std" and a.shape[1] == 1) else a[:, :k]

        return PolicyOutput(**{f.name: cut(f.name) for f in dataclasses.fields(self)})


@dataclass(frozen=True)
class Scorer:
    """A named scoring function and the outputs it can work from.

    Attributes:
        name: Registry name (``--scorer NAME``).
        fn: ``fn(output, actions) -> (K,)`` scores.
        needs: Alternative sets of :class:`PolicyOutput` fields; any one suffices.
        description: One line for ``grail-bench list scorers``.
        posterior: Whether the scores are mean log-likelihoods, so that
            :func:`posterior` turns them into a posterior over goals (the
            harness then records its Brier score and NLL).
        steps: Optional ``steps(output, actions) -> (K, T)`` per-step scores
            whose mean over steps is ``fn``; with it, every prefix of an
            observation is scored from one pass (online mode). Without it the
            harness slices the outputs per prefix.
    """

    name: str
    fn: Callable[[PolicyOutput, np.ndarray], np.ndarray]
    needs: tuple[frozenset[str], ...]
    description: str
    posterior: bool = False
    steps: Callable[[PolicyOutput, np.ndarray], np.ndarray] | None = None

    def scores(self, output: PolicyOutput, actions: np.ndarray, n_goals: int) -> np.ndarray:
        """``fn``'s ``(K,)`` scores of one observation, checked.

        Raises:
            UserError: Unless ``fn`` returned ``n_goals`` real numbers.
        """
        return self._checked(self.fn(output, actions), (n_goals,), "fn")

    def prefix_scores(self, output: PolicyOutput, actions: np.ndarray, n_goals: int | None = None) -> np.ndarray:
        """Scores of every prefix ``k = 1..T`` of an observation, ``(K, T)``, from outputs on all ``T`` steps
        (checked to be ``(n_goals, T)`` real numbers when ``n_goals`` is given)."""
        if self.steps is not None:
            if n_goals is not None:
                steps = self._checked(self.steps(output, actions), (n_goals, len(actions)), "steps")
                return prefix_means(steps)
            return prefix_means(self.steps(output, actions))
        columns = [self.fn(output.head(k), actions[:k]) if n_goals is None else
                   self.scores(output.head(k), actions[:k], n_goals) for k in range(1, len(actions) + 1)]
        return np.stack(columns, axis=1)

    def _checked(self, values: object, shape: tuple[int, ...], what: str) -> np.ndarray:
        """``values`` as a float array of ``shape``, refused when it is anything else (text, flags, more or fewer
        scores than goals): a plugin's mistake must not be stored as a row of ties."""
        array = np.asarray(values) if not isinstance(values, np.ndarray) else values
        if array.dtype.kind not in "iuf":
            raise UserError(f"scorer {self.name!r} must return numbers from {what}, got {array.dtype} values")
        if array.shape != shape:
            raise UserError(f"scorer {self.name!r} returned shape {array.shape} from {what}; expected {shape} "
                            f"(one score per goal{'' if len(shape) == 1 else ' and step'})")
        return array.astype(np.float64, copy=False)

    def can_serve(self, exposes: frozenset[str]) -> bool:
        return any(need <= exposes for need in self.needs)

    def needs_text(self) -> str:
        order = list(OUTPUT_NAMES)  # each need's outputs in this order
        return " or ".join(" and ".join(OUTPUT_NAMES[n] for n in sorted(need, key=order.index)) for need in self.needs)


# ----------------------------------------------------------------------------- pure functions


def one_hot(actions: np.ndarray, n: int) -> np.ndarray:
    """``(T,)`` integer actions -> ``(T, n)`` one-hot rows."""
    out = np.zeros((len(actions), n), dtype=np.float32)
    out[np.arange(len(actions)), actions] = 1.0
    return out


def mse_steps(predicted: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Per-step negative squared error between predicted and observed actions.

    Args:
        predicted: ``(K, T, A)`` policy outputs (action probabilities for
            discrete actions, mean actions for continuous ones).
        observed: ``(T, A)`` observed actions (one-hot for discrete actions).

    Returns:
        ``(K, T)``: ``-mean_a (predicted - observed)^2`` at every step.
    """
    diff = predicted - observed[None]
    return -np.mean(diff * diff, axis=2)


def neg_mse(predicted: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Negative mean squared error over steps and action components, ``(K,)`` (see :func:`mse_steps`)."""
    return mse_steps(predicted, observed).mean(axis=1)


def kl_steps(probs: np.ndarray, actions: np.ndarray, *, eps: float = 0.01) -> np.ndarray:
    """GRAQL's per-step score: minus KL(observed pseudo-policy || policy), ``(K, T)``.

    The pseudo-policy of each observed step puts ``1 - eps`` on the observed
    action and spreads ``eps`` over the others.
    """
    n = probs.shape[-1]
    pseudo = np.full((len(actions), n), eps / (n - 1))
    pseudo[np.arange(len(actions)), actions] = 1.0 - eps
    log_ratio = np.log(pseudo)[None] - np.log(np.clip(probs, EPS, None))
    return -np.sum(pseudo[None] * log_ratio, axis=-1)


def neg_kl(probs: np.ndarray, actions: np.ndarray, *, eps: float = 0.01) -> np.ndarray:
    """GRAQL's score: minus the mean KL over steps, ``(K,)`` (see :func:`kl_steps`)."""
    return kl_steps(probs, actions, eps=eps).mean(axis=1)


def wasserstein_discrete_steps(probs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Minus the 1-Wasserstein distance between each step's categorical policy
    and the point mass on the observed action, actions placed at their
    indices on the real line (as ``scipy.stats.wasserstein_distance`` would):
    ``W1 = sum_i p_i |i - a|``; ``(K, T)``."""
    distance = np.abs(np.arange(probs.shape[-1])[None, :] - actions[:, None])  # (T, A)
    return -np.sum(probs * distance[None], axis=-1)


def neg_wasserstein_discrete(probs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Mean over steps of :func:`wasserstein_discrete_steps`, ``(K,)``."""
    return wasserstein_discrete_steps(probs, actions).mean(axis=1)


def wasserstein_gaussian_steps(mean: np.ndarray, std: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Minus the 1-Wasserstein distance between ``N(mean, std^2)`` and the
    point mass on the observed action, averaged over action dimensions, in
    closed form: ``E|X - a| = s*sqrt(2/pi)*exp(-z^2/2) + (a - m)*erf(z/sqrt(2))``
    with ``z = (a - m) / s``; ``(K, T)``."""
    from scipy.special import erf  # here: the report imports this module, not scipy.special

    diff = actions[None] - mean
    std = np.broadcast_to(std, diff.shape)
    z = diff / std
    w1 = std * np.sqrt(2 / np.pi) * np.exp(-0.5 * z * z) + diff * erf(z / np.sqrt(2))
    return -np.mean(w1, axis=2)


def neg_wasserstein_gaussian(mean: np.ndarray, std: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Mean over steps of :func:`wasserstein_gaussian_steps`, ``(K,)``."""
    return wasserstein_gaussian_steps(mean, std, actions).mean(axis=1)


def loglik_discrete_steps(probs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Log-probability of each observed action, ``(K, T)``."""
    picked = probs[:, np.arange(len(actions)), actions]
    return np.log(np.clip(picked, EPS, None))


def loglik_discrete(probs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Mean log-probability of the observed actions, ``(K,)``."""
    return loglik_discrete_steps(probs, actions).mean(axis=1)


def loglik_gaussian_steps(mean: np.ndarray, std: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Gaussian log-density of each observed action, summed over dimensions, ``(K, T)``."""
    z = actions[None] - mean
    z /= std  # a (K, 1, D) std (one per goal) broadcasts without being copied out to (K, T, D)
    out = np.einsum("ktd,ktd->kt", z, z)
    out *= -0.5
    out -= np.log(std).sum(axis=-1) + 0.5 * mean.shape[-1] * math.log(2 * math.pi)
    return out


def loglik_gaussian(mean: np.ndarray, std: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Mean over steps of :func:`loglik_gaussian_steps`, ``(K,)``."""
    return loglik_gaussian_steps(mean, std, actions).mean(axis=1)


def posterior(scores: np.ndarray, n_steps: int) -> np.ndarray:
    """Posterior over goals from mean log-likelihoods: softmax of their sums (uniform prior)."""
    from scipy.special import softmax  # here: the report imports this module, not scipy.special

    return softmax(scores * n_steps)


def prefix_means(steps: np.ndarray) -> np.ndarray:
    """Scores of every prefix from per-step scores: ``(K, T) -> (K, T)``, column ``k - 1`` the mean of the first ``k``."""
    return np.cumsum(steps, axis=1) / np.arange(1, steps.shape[1] + 1)


# ----------------------------------------------------------------------------- adapters and registry


def mse_probs_steps(probs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """:func:`mse_steps` of action probabilities against one-hot observed actions, without building them:
    ``sum_a (p_a - [a = y])^2 = sum_a p_a^2 - 2 p_y + 1``; ``(K, T)``."""
    picked = probs[:, np.arange(len(actions)), actions]
    squared = np.einsum("kta,kta->kt", probs, probs)
    squared -= 2.0 * picked  # in place: this runs once per scored observation
    squared += 1.0
    return np.divide(squared, -probs.shape[-1], out=squared)


def _mse(out: PolicyOutput, actions: np.ndarray) -> np.ndarray:
    if out.probs is not None:
        return mse_probs_steps(out.probs, np.asarray(actions, dtype=np.int64))
    return mse_steps(out.mean, actions.reshape(len(actions), -1).astype(out.mean.dtype))


def _wasserstein(out: PolicyOutput, actions: np.ndarray) -> np.ndarray:
    if out.probs is not None:
        return wasserstein_discrete_steps(out.probs, np.asarray(actions, dtype=np.int64))
    return wasserstein_gaussian_steps(out.mean, out.std, actions.reshape(len(actions), -1))


def _kl(out: PolicyOutput, actions: np.ndarray) -> np.ndarray:
    return kl_steps(out.probs, np.asarray(actions, dtype=np.int64))


def _loglik(out: PolicyOutput, actions: np.ndarray) -> np.ndarray:
    if out.probs is not None:
        return loglik_discrete_steps(out.probs, np.asarray(actions, dtype=np.int64))
    return loglik_gaussian_steps(out.mean, out.std, actions.reshape(len(actions), -1))


def _occupancy(out: PolicyOutput, actions: np.ndarray) -> np.ndarray:
    return _loglik(out, actions) + out.log_occupancy


def _builtin(name: str, steps: Callable[[PolicyOutput, np.ndarray], np.ndarray], needs: tuple[frozenset[str], ...],
             description: str, posterior: bool = False) -> Scorer:
    """A built-in scorer: the mean over steps of its per-step scores."""
    def mean_over_steps(out: PolicyOutput, actions: np.ndarray) -> np.ndarray:
        per_step = steps(out, actions)
        return per_step.sum(axis=1) / per_step.shape[1]  # what .mean(axis=1) computes, without its overhead

    return Scorer(name, mean_over_steps, needs, description, posterior, steps)


_PROBS, _GAUSS = frozenset({"probs"}), frozenset({"mean", "std"})
BUILTIN: dict[str, Scorer] = {
    s.name: s for s in (
        _builtin("mse", _mse, (_PROBS, frozenset({"mean"})),
               "negative MSE between the policy's action (probabilities vs one-hot, or mean) and the observed one (GRAIL)"),
        _builtin("wasserstein", _wasserstein, (_PROBS, _GAUSS),
               "negative 1-Wasserstein distance between the action distribution and the observed action (DRACO)"),
        _builtin("kl", _kl, (_PROBS,),
               "negative KL between the observed pseudo-policy and the policy's action probabilities (GRAQL)"),
        _builtin("loglik", _loglik, (_PROBS, _GAUSS),
               "mean log-likelihood of the observed actions; also yields a posterior, its Brier score and NLL",
               posterior=True),
        _builtin("occupancy", _occupancy, (_PROBS | {"occupancy"}, _GAUSS | {"occupancy"}),
               "mean of log pi_g(a|s) + log d_g(s), d_g goal g's smoothed state occupancy in its training "
               "demonstrations; also yields a posterior", posterior=True),
    )
}


class UnknownScorerError(UserError):
    """No scorer is registered under the requested name."""


def _checked(obj: object, target: str) -> Scorer:
    if not isinstance(obj, Scorer):
        raise UserError(f"scorer entry point {target} is not a grail_bench.Scorer")
    return obj


#: Every scorer: the built-in ones and those of the ``grail_bench.scorers`` entry points.
SCORERS: Registry[Scorer] = Registry("scorer", GROUP, check=_checked, unknown=UnknownScorerError)
for _name, _scorer in BUILTIN.items():
    SCORERS.add(_name, _scorer)


def available_scorers() -> dict[str, str]:
    """Scorer names and what provides them (plugins are not imported)."""
    return SCORERS.targets()


def get_scorer(name: str) -> Scorer:
    """The scorer registered under ``name``.

    Raises:
        UnknownScorerError: For an unregistered name.
    """
    return SCORERS.get(name)


def check_scorer(name: str, exposes: frozenset[str], recognizer: str) -> Scorer:
    """The scorer ``name``, if a recognizer exposing ``exposes`` can serve it.

    The one compatibility check: the harness runs it when planning, and
    recognizers when scoring.

    Raises:
        UnknownScorerError: For an unregistered name.
        UserError: If the recognizer does not expose what the scorer needs.
    """
    return check_served(get_scorer(name), exposes, recognizer, name)


def check_served(scorer: Scorer, exposes: frozenset[str], recognizer: str, name: str | None = None) -> Scorer:
    """``scorer``, if a recognizer exposing ``exposes`` can serve it (:func:`check_scorer` for a scorer in hand,
    asked for as ``name``, its own name by default).

    Raises:
        UserError: If the recognizer does not expose what the scorer needs.
    """
    name = scorer.name if name is None else name
    if not scorer.can_serve(exposes):
        offered = ", ".join(sorted(exposes)) or "nothing"
        raise UserError(f"scorer {name!r} needs {scorer.needs_text()}; recognizer {recognizer!r} exposes {offered}"
                        + ("" if exposes else " (it scores with its own default scorer only)"))
    return scorer
