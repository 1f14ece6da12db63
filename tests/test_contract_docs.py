"""The recognizer contract's optional members are documented in one place, the one the harness reads.

:class:`~grail_bench.recognizers.contract.OptionalCapabilities` documents every optional member (the docs'
plugin guide is generated from it); these tests fail when the harness reads a member it does not document, or
ignores one it documents.
"""

from __future__ import annotations

import inspect

import gymnasium as gym

from grail_bench.recognizers.contract import DEFAULT_CHANNELS, OWN_SCORING, OptionalCapabilities, capabilities

REQUIRED = {"fit", "score"}


def documented() -> tuple[set[str], set[str]]:
    """The attributes and the methods OptionalCapabilities documents."""
    attributes = set(OptionalCapabilities.__annotations__)
    methods = {n for n, f in vars(OptionalCapabilities).items() if inspect.isfunction(f) and not n.startswith("_")}
    return attributes, methods


class Recording:
    """A recognizer with the required methods only, noting every other member the harness asks it for."""

    asked: set[str]

    def __init__(self) -> None:
        object.__setattr__(self, "asked", set())

    def fit(self, demos, env_factory=None, *, seed=0):
        return None

    def score(self, observed):
        return {}

    def __getattr__(self, name: str):
        self.asked.add(name)
        raise AttributeError(name)


def test_every_optional_member_the_harness_reads_is_documented():
    attributes, methods = documented()
    rec = Recording()
    caps = capabilities(rec, "recording")
    caps.exposes(gym.spaces.Discrete(4))
    caps.check_task(None)
    assert caps.score_prefixes(None) is None and caps.diagnose({}, {}, None) is None
    assert rec.asked and rec.asked <= attributes | methods, rec.asked - attributes - methods
    assert not (attributes | methods) & REQUIRED
    assert len(attributes | methods) >= 11  # the module docstring's list, nothing lost in the move


def test_without_them_every_documented_default_holds():
    caps = capabilities(Recording(), "recording")
    assert (caps.info.paper_name, caps.info.reference, caps.default_scorer) == ("recording", False, OWN_SCORING)
    assert caps.channels == DEFAULT_CHANNELS == {"pairs"} and caps.exposes(gym.spaces.Discrete(4)) == frozenset()
    assert not (caps.takes_scorer or caps.takes_cache_key or caps.has_prefix_scores or caps.has_diagnostics
                or caps.has_set_goals or caps.has_check_task)
    assert dict(caps.config) == {}


def test_a_recognizer_declaring_every_documented_member_is_read_as_declaring_it():
    attributes, methods = documented()
    values = {"name": "full", "paper_name": "Full (2026)", "reference": True, "config": {"k": 1},
              "default_scorer": "mse", "channels": frozenset({"states", "pairs"})}
    assert set(values) == attributes  # a new documented attribute needs a value here, and a reading below
    members = {**values, **{m: (lambda self, *a, **k: None) for m in methods},
               "exposes": lambda self, space: frozenset({"probs"}),
               "fit": lambda self, demos, env_factory=None, *, seed=0, cache_key=None: None,
               "score": lambda self, observed, scorer=None: {}}
    caps = capabilities(type("Full", (), members)(), "full")
    assert (caps.info.paper_name, caps.info.reference, caps.default_scorer) == ("Full (2026)", True, "mse")
    assert caps.channels == {"states", "pairs"} and dict(caps.config) == {"k": 1}
    assert caps.exposes(gym.spaces.Discrete(4)) == {"probs"}
    assert caps.takes_scorer and caps.takes_cache_key
    assert caps.has_prefix_scores and caps.has_diagnostics and caps.has_set_goals and caps.has_check_task
