"""The scorecard's statistics (adaptive_mj.study.stats): laws compared by the paired t interval of their per-seed
difference, checked against scipy computed here by hand, and score.rank_laws writing ranks and counts into a
hand-made plant entry (no runs)."""
import math
from typing import Any

import numpy as np
import pytest
from scipy import stats as sps

from adaptive_mj.study.stats import (RANKING, differs, estimate, paired_difference, paired_ranks, separable,
                                     separated_pairs)


def _t_interval(d: np.ndarray) -> tuple[float, float, float]:
    """mean, lo, hi of the 95 % t interval of d, by hand."""
    n = d.size
    mean = float(np.sum(d) / n)
    sd = math.sqrt(float(np.sum((d - mean) ** 2)) / (n - 1))
    half = sps.t.ppf(0.975, n - 1) * sd / math.sqrt(n)
    return mean, mean - half, mean + half


def test_the_paired_interval_is_the_t_interval_of_the_per_seed_differences():
    a = [0.81, 0.77, 0.90, 0.62, 0.85]
    b = [0.80, 0.73, 0.86, 0.63, 0.81]
    d = paired_difference(a, b)
    mean, lo, hi = _t_interval(np.array(a) - np.array(b))
    assert d.n == 5
    assert math.isclose(d.mean, mean, rel_tol=1e-12)
    assert math.isclose(d.lo, lo, rel_tol=1e-9) and math.isclose(d.hi, hi, rel_tol=1e-9)
    # the interval excludes 0 exactly when scipy's paired t test rejects at 5 %
    assert differs(d) == (sps.ttest_rel(a, b).pvalue < 0.05)


@pytest.mark.parametrize("shift", [0.0, 0.005, 0.02, -0.03])
def test_separable_agrees_with_scipy_s_paired_t_test(shift):
    rng = np.random.default_rng(7)
    common = rng.normal(0.7, 0.1, size=6)
    a = common + shift + rng.normal(0.0, 0.01, size=6)
    b = common + rng.normal(0.0, 0.01, size=6)
    assert differs(paired_difference(a.tolist(), b.tolist())) == (sps.ttest_rel(a, b).pvalue < 0.05)


def test_copies_of_one_law_tie_alone_and_beside_a_third_law():
    a = [0.71, 0.64, 0.93, 0.58]
    d = paired_difference(a, list(a))
    assert (d.mean, d.lo, d.hi, d.n) == (0.0, 0.0, 0.0, 4)
    assert not differs(d)
    assert paired_ranks([a, list(a)]) == [1, 1]
    better = [v + 0.05 for v in a]
    assert paired_ranks([a, better, list(a)]) == [2, 1, 2]
    assert paired_ranks([a, better, list(a)], higher_is_better=False) == [1, 3, 1]


def test_a_small_advantage_on_every_seed_separates_where_the_unpaired_intervals_overlap():
    seeds = np.array([0.55, 0.80, 0.62, 0.91, 0.70])  # the seeds' common variation: some draws are harder
    noise = np.array([0.002, -0.001, 0.0, 0.001, -0.002])
    a = (seeds + 0.01 + noise).tolist()  # +0.01 on every seed, noise smaller than that
    b = seeds.tolist()
    # unpaired, by hand: each law's own t interval, and they overlap (the old rule: a tie)
    _, a_lo, a_hi = _t_interval(np.array(a))
    _, b_lo, b_hi = _t_interval(np.array(b))
    assert a_lo < b_hi and b_lo < a_hi
    assert not separable(estimate(a), estimate(b))
    # paired: the common variation cancels
    mean, lo, _ = _t_interval(np.array(a) - np.array(b))
    assert lo > 0
    assert differs(paired_difference(a, b))
    assert paired_ranks([b, a]) == [2, 1]
    assert separated_pairs([b, a]) == 1


def test_a_seed_with_no_value_on_either_side_is_left_out_of_that_pair():
    a = [0.9, math.nan, 0.8, 0.7]
    b = [0.8, 0.5, math.inf, 0.6]
    c = [0.85, 0.4, 0.75, 0.66]
    d = paired_difference(a, b)
    assert d.n == 2  # seeds 0 and 3: a constant difference of 0.1 on both
    mean, lo, hi = _t_interval(np.array([0.9 - 0.8, 0.7 - 0.6]))
    assert math.isclose(d.mean, mean) and math.isclose(d.lo, lo) and math.isclose(d.hi, hi)
    assert paired_difference(a, c).n == 3 and paired_difference(b, c).n == 3
    with pytest.raises(ValueError, match="same seeds for both laws, got 2 and 3"):
        paired_difference([1.0, 2.0], [1.0, 2.0, 3.0])


def test_a_constant_nonzero_difference_separates_and_fewer_than_two_seeds_do_not():
    a = [0.5, 0.7, 0.6]
    b = [0.25, 0.45, 0.35]  # a − b = 0.25 on every seed
    d = paired_difference(a, b)
    assert d.n == 3 and math.isclose(d.mean, 0.25) and d.hi - d.lo < 1e-12
    assert differs(d) and differs(paired_difference(b, a))
    one = paired_difference([0.9, math.nan], [0.1, 0.2])
    assert one.n == 1 and not differs(one)
    assert not differs(paired_difference([math.nan, math.nan], [0.1, 0.2]))
    assert paired_ranks([[0.9, math.nan], [0.1, 0.2]]) == [1, 1]


def test_the_separated_pair_count_and_ranks_on_a_three_law_example():
    base = np.array([0.4, 0.6, 0.5, 0.8])
    top = (base + np.array([0.2, 0.21, 0.19, 0.2])).tolist()  # above both others on every seed by about 0.2
    mid = (base + np.array([0.01, -0.01, 0.0, 0.005])).tolist()  # no steady difference from low
    low = base.tolist()
    # by hand: top − mid and top − low exclude 0; mid − low does not (scipy's paired test says the same)
    for x, y, sep in ((top, mid, True), (top, low, True), (mid, low, False)):
        _, lo, hi = _t_interval(np.array(x) - np.array(y))
        assert (lo > 0 or hi < 0) == sep == (sps.ttest_rel(x, y).pvalue < 0.05)
    assert separated_pairs([top, mid, low]) == 2
    assert paired_ranks([top, mid, low]) == [1, 2, 2]
    assert paired_ranks([top, mid, low], higher_is_better=False) == [3, 1, 1]
    assert paired_ranks([top, mid, low, [math.nan] * 4]) == [1, 2, 2, 4]  # no value: last


def test_ranks_do_not_depend_on_the_order_the_laws_come_in():
    rng = np.random.default_rng(3)
    common = rng.normal(0.6, 0.15, size=5)
    laws = [(common + off + rng.normal(0.0, 0.004, size=5)).tolist() for off in (0.0, 0.0, 0.02, 0.05, 0.05)]
    r = paired_ranks(laws)
    for perm in ([4, 3, 2, 1, 0], [2, 0, 4, 1, 3]):
        assert paired_ranks([laws[i] for i in perm]) == [r[i] for i in perm]
    assert r[0] == r[1] and r[3] == r[4]  # laws sharing a rank keep sharing it in any order


def test_rank_laws_writes_the_ranks_the_rule_and_the_counts_into_a_plant_entry():
    from adaptive_mj.study.score import rank_laws

    def law(perf, rob):
        def fig(values):
            return {**estimate([math.nan if v is None else v for v in values]).as_dict(), "values": values}

        return {"figures": {"performance": fig(perf), "robustness": fig(rob)}}

    perf = [0.61, 0.75, 0.52]
    rob = [0.40, 0.45, 0.50]
    plant: dict[str, Any] = {"laws": {"adaptive": law(perf, rob),
                      "twin": law(list(perf), list(rob)),
                      "better": law([v + 0.03 for v in perf], [None, 0.46, 0.51]),  # null: a seed with no value
                      "none": law([0.0, 0.0, 0.0], [None, None, None])}}
    rank_laws(plant)
    got = {lb: e["rank"] for lb, e in plant["laws"].items()}
    assert got == {"adaptive": {"performance": 2, "robustness": 2}, "twin": {"performance": 2, "robustness": 2},
                   "better": {"performance": 1, "robustness": 1}, "none": {"performance": 4, "robustness": 4}}
    # S: better beats the other three and the twins beat none (constant differences); R: better − adaptive is a
    # constant 0.01 on its two seeds with a value, so it separates too, from both copies
    assert plant["separated_pairs"] == {"performance": 5, "robustness": 2, "pairs": 6}
    assert plant["ranking"] == RANKING == "paired t, 95 %"


def test_the_card_s_scoring_paragraph_names_the_rule_and_the_counts_per_plant():
    from adaptive_mj.study.score_card import formula_text

    data = {"suite": {"steps": 6, "seeds": 3, "confidence": 0.95},
            "plants": {"heave": {"separated_pairs": {"performance": 12, "robustness": 9, "pairs": 28}},
                       "arm": {"separated_pairs": {"performance": 3, "robustness": 1, "pairs": 21}}}}
    text = formula_text(data)
    assert "Ranks (paired t, 95 %)" in text
    assert "Pairs that separate: heave S 12 and R 9 of 28; arm S 3 and R 1 of 21." in text
