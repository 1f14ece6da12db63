"""Goal-agnostic scorers: pure functions from policy outputs to one score per goal.

Every scorer takes the policies' outputs on the observed states, stacked over
goals, and the observed actions, and returns one score per goal; higher means
the observations fit that goal's policy better.

Shapes: ``K`` goals, ``T`` observed steps, ``A`` actions (discrete) or action
dimensions (continuous).
"""

from __future__ import annotations

import numpy as np

EPS = 1e-8


def one_hot(actions: np.ndarray, n: int) -> np.ndarray:
    """``(T,)`` integer actions -> ``(T, n)`` one-hot rows."""
    out = np.zeros((len(actions), n))
    out[np.arange(len(actions)), actions] = 1.0
    return out


def neg_mse(predicted: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Negative mean squared error between predicted and observed actions.

    Args:
        predicted: ``(K, T, A)`` policy outputs (action probabilities for
            discrete actions, mean actions for continuous ones).
        observed: ``(T, A)`` observed actions (one-hot for discrete actions).

    Returns:
        ``(K,)`` scores, ``-mean_t mean_a (predicted - observed)^2``.
    """
    diff = predicted - observed[None]
    return -np.mean(diff * diff, axis=(1, 2))


def neg_kl(probs: np.ndarray, actions: np.ndarray, *, eps: float = 0.01) -> np.ndarray:
    """GRAQL's score: minus the mean KL(observed pseudo-policy || policy).

    The pseudo-policy of each observed step puts ``1 - eps`` on the observed
    action and spreads ``eps`` over the others.

    Args:
        probs: ``(K, T, A)`` action probabilities of each goal's policy.
        actions: ``(T,)`` observed discrete actions.
        eps: Mass the pseudo-policy leaves to unobserved actions.

    Returns:
        ``(K,)`` scores, ``-mean_t KL(p_obs,t || probs[k, t])``.
    """
    n = probs.shape[-1]
    pseudo = np.full((len(actions), n), eps / (n - 1))
    pseudo[np.arange(len(actions)), actions] = 1.0 - eps
    log_ratio = np.log(pseudo)[None] - np.log(np.clip(probs, EPS, None))
    return -np.mean(np.sum(pseudo[None] * log_ratio, axis=-1), axis=1)
