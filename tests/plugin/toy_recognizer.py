"""A third-party recognizer, as a plugin package would ship it (no grail_bench import)."""

from __future__ import annotations

import os

import numpy as np


class LookupRecognizer:
    """Scores a goal by the fraction of observed state-action pairs seen in its demos."""

    name = "toy"
    default_scorer = "default"  # its own scoring; no pluggable scorers

    def __init__(self, smoothing: float = 0.0, bug: bool = False, crash_marker: str = "") -> None:
        self.config = {"smoothing": smoothing}
        self.bug = bug  # raise a plain ValueError in fit, as a bug in a recognizer would
        self.crash_marker = crash_marker  # the first fit of seed 1 kills its process, as a dying worker would
        self.seen: dict = {}

    def exposes(self, action_space):
        return frozenset()

    def fit(self, demos, env_factory, *, seed, cache_key=None):
        if self.bug:
            raise ValueError("an internal error")
        if self.crash_marker and seed == 1 and not os.path.exists(self.crash_marker):
            open(self.crash_marker, "w").close()
            os._exit(9)
        self.seen = {
            goal: {(tuple(np.asarray(o).tolist()), int(a)) for t in trajs for o, a in zip(t.obs[:-1], t.acts)}
            for goal, trajs in demos.items()
        }

    def score(self, observed, scorer=None):
        pairs = [(tuple(np.asarray(o).tolist()), int(a)) for o, a in zip(observed.obs[:-1], observed.acts)]
        return {g: (sum(p in s for p in pairs) + self.config["smoothing"]) / len(pairs) for g, s in self.seen.items()}
