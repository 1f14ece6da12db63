"""The paper's headline claims checked against stored runs: intervals, verdicts, and which runs count."""

from __future__ import annotations

import math

import pytest
from conftest import offline_record

from grail_bench.core.errors import UserError
from grail_bench.harness.modes.offline import OfflineRecord
from grail_bench.report.claims import CLAIMS, claims_markdown, headline_claims, verdict

BIASED = "GRAIL/MiniGrid-Biased-v0"
LEVELS = (0.2, 0.3, 0.4)
NEAR_PERFECT, GRAQL_CHANCE, BIASED_GAIN = (c.claim for c in CLAIMS[:3])
PANDA_OPTIMAL = "GRAIL/PandaReach-Optimal-v0"


def biased(name: str, f1: tuple[float, ...], **kwargs) -> list[OfflineRecord]:
    """``name``'s records at every level of the paper's biased task, each with the same per-seed F1 (``kwargs``: as
    :func:`conftest.offline_record` takes them)."""
    return [offline_record(BIASED, name, level, f1, **kwargs) for level in LEVELS]


def row(results, claim: str, configuration: str):
    (found,) = [r for r in results if r.claim == claim and r.configuration == configuration]
    return found


@pytest.fixture(scope="module")
def runs() -> list[OfflineRecord]:
    """BC-GRAIL perfect on the biased task, GRAQL at 0.9; a scorer variant of BC; GRAQL's KL spread around 0.5."""
    return (biased("bc", (1.0,) * 6) + biased("graql", (0.9,) * 6)
            + biased("bc", (1.0, 1.0, 1.0, 0.8, 1.0, 1.0), scorer="kl")
            + biased("graql", (0.2, 0.8) * 5, scorer="mse"))


@pytest.fixture(scope="module")
def results(runs):
    return headline_claims(runs, reps=500)


def test_a_claim_the_runs_clearly_support_holds(results):
    near_perfect = row(results, NEAR_PERFECT, "BC-GRAIL")
    assert near_perfect.verdict == "holds"
    assert near_perfect.estimate == pytest.approx(1.0) and near_perfect.low == pytest.approx(1.0)


def test_a_claim_the_runs_clearly_refute_does_not_hold(results):
    graql = row(results, GRAQL_CHANCE, "GRAQL")  # 0.9 against a claimed 0.3-0.5
    assert graql.verdict == "does not hold" and graql.estimate == pytest.approx(0.9)
    gain = row(results, BIASED_GAIN, "BC-GRAIL")  # 1.0 - 0.9 on every seed, claimed above 0.5
    assert gain.verdict == "does not hold" and gain.estimate == pytest.approx(0.1)
    assert gain.low == pytest.approx(0.1) and gain.high == pytest.approx(0.1)


def test_an_interval_straddling_the_claimed_range_holds_partly(results):
    spread = row(results, GRAQL_CHANCE, "GRAQL · mse")  # per-seed 0.2 / 0.8, mean 0.5
    assert spread.estimate == pytest.approx(0.5)
    assert spread.low < 0.5 < spread.high and spread.verdict == "partly"


def test_named_variants_get_their_own_rows_and_gains_are_over_the_canonical_baseline(results):
    variant = row(results, BIASED_GAIN, "BC-GRAIL · kl")
    assert variant.estimate == pytest.approx((1.0 * 5 + 0.8) / 6 - 0.9)
    assert not [r for r in results if r.configuration.startswith("GRAQL") and r.claim == BIASED_GAIN]


def test_gains_pair_the_seeds_both_configurations_ran():
    runs = biased("bc", (1.0, 0.5, 0.5), seeds=[0, 1, 2]) + biased("graql", (0.0, 0.5, 0.0), seeds=[1, 2, 3])
    gain = row(headline_claims(runs, reps=200), BIASED_GAIN, "BC-GRAIL")
    assert gain.estimate == pytest.approx(0.25)  # seeds 1 and 2: 0.5 - 0.0 and 0.5 - 0.5


def test_claims_without_their_strata_are_not_measured_but_still_listed(results):
    suboptimal = [r for r in results if "suboptimal" in r.claim]
    assert suboptimal and all(r.verdict == "not measured" and math.isnan(r.estimate) for r in suboptimal)
    assert "BC-GRAIL · kl" not in {r.configuration for r in suboptimal}  # a variant is listed where it ran
    # every canonical GRAIL method is listed on every claim about GRAIL, run or not
    assert {r.configuration for r in results if r.claim == NEAR_PERFECT} >= {"BC-GRAIL", "GAIL-GRAIL", "AIRL-GRAIL"}
    assert row(results, NEAR_PERFECT, "GAIL-GRAIL").verdict == "not measured"


def test_a_missing_level_or_baseline_leaves_the_claim_not_measured():
    runs = [offline_record(BIASED, "bc", level, (1.0, 1.0)) for level in LEVELS[:2]] + biased("graql", (0.5, 0.5))
    results = headline_claims(runs, reps=200)
    near_perfect = row(results, NEAR_PERFECT, "BC-GRAIL")
    assert near_perfect.verdict == "not measured" and "2 of 3" in near_perfect.measured
    no_baseline = headline_claims(biased("bc", (1.0, 1.0)), reps=200)
    assert row(no_baseline, BIASED_GAIN, "BC-GRAIL").verdict == "not measured"
    assert row(no_baseline, NEAR_PERFECT, "BC-GRAIL").verdict == "holds"


def test_archived_configurations_and_other_protocols_are_left_out():
    runs = (biased("bc", (0.0, 0.0), config_hash="0123456789abcdef")  # an earlier version's run
            + biased("bc", (0.0, 0.0), protocol="prefix+floor"))
    results = headline_claims(runs, reps=200)
    assert not [r for r in results if "archived" in r.configuration]
    assert row(results, NEAR_PERFECT, "BC-GRAIL").verdict == "not measured"


def test_same_records_same_table(runs, results):
    assert repr(headline_claims(runs, reps=500)) == repr(results)  # repr: NaN (not measured) equals itself
    assert claims_markdown(headline_claims(runs, reps=500)) == claims_markdown(results)


def test_verdict_rules_at_the_ends_of_the_claimed_range():
    assert verdict(0.91, 1.0, 0.9, 1.0) == "holds"
    assert verdict(0.85, 0.95, 0.9, 1.0) == "partly"
    assert verdict(0.2, 0.25, 0.3, 0.5) == "does not hold" and verdict(0.6, 0.7, 0.3, 0.5) == "does not hold"
    assert verdict(0.5, 0.7, 0.5, math.inf) == "holds"
    assert verdict(0.5, 0.7, 0.5, math.inf, strict=True) == "partly"  # "more than 0.5": 0.5 is not enough
    assert verdict(0.3, 0.5, 0.5, math.inf, strict=True) == "does not hold"
    assert verdict(math.nan, math.nan, 0.0, 1.0) == "not measured"


def test_the_largest_gain_over_draco_is_read_from_the_best_noisy_condition():
    tasks = ("GRAIL/PandaReach-Gaussian-0.1-v0", "GRAIL/PandaReach-Gaussian-0.3-v0",
             "GRAIL/PandaReach-Uniform-0.1-v0", "GRAIL/PandaReach-Uniform-0.3-v0")
    gains = (0.1, 0.4, 0.0, 0.2)
    runs = [r for task, gain in zip(tasks, gains)
            for r in (offline_record(task, "bc", 0.02, (0.5 + gain,) * 4),
                      offline_record(task, "draco", 0.02, (0.5,) * 4))]
    (noisy,) = [r for r in headline_claims(runs, reps=200) if r.configuration == "BC-GRAIL" and "noisy" in r.claim]
    assert noisy.estimate == pytest.approx(0.4) and noisy.verdict == "holds"


def test_markdown_states_the_rules_and_one_row_per_result(results):
    text = claims_markdown(results)
    assert "*holds*: the whole interval lies inside the claimed range" in text
    assert "- *near perfect*: F1 >= 0.9" in text and "at least -0.05 F1" in text
    assert "| BC-GRAIL | mean F1, MiniGrid biased (2 goals) x 20/30/40 % | 1.00 [1.00, 1.00] | **holds** |" in text
    assert text.count("\n| ") == len(results) + 2  # the header, its rule, and one line per result


def test_bad_replicate_count_is_refused():
    with pytest.raises(UserError, match="reps"):
        headline_claims([], reps=0)
