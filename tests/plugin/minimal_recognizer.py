"""The smallest third-party recognizer the contract accepts: a name, fit and score (no grail_bench import)."""

from __future__ import annotations

import numpy as np


class NearestStart:
    """Scores a goal by how close the observed states come to the states of its demonstrations."""

    name = "minimal"

    def fit(self, demos, env_factory=None, *, seed=0):
        self.states = {goal: np.concatenate([np.asarray(t.obs, dtype=float) for t in trajs]) for goal, trajs in demos.items()}

    def score(self, observed):
        obs = np.asarray(observed.obs, dtype=float)
        return {g: -float(np.mean([np.abs(s - o).sum(axis=1).min() for o in obs])) for g, s in self.states.items()}
