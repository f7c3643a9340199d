"""Statistics over seeds for the scorecard: a mean with its Student-t confidence interval, and ranks by paired
comparison that say when two laws cannot be told apart at that confidence.

A figure measured on n seeds x_1..x_n is reported as mean ± t_{1-α/2, n-1} · s / √n (s the sample standard
deviation, α = 1 − CONFIDENCE).

Every law on a card runs the same seeds: seed k of every law sees the same noise draw (and the same drawn task), so
two laws are compared seed by seed. Their *paired difference* is d_k = a_k − b_k over the seeds where both gave a
finite value (n of them), reported as mean(d) ± t_{1-α/2, n-1} · s_d / √n: the paired t interval. Two laws are
*separable* on a figure when that interval excludes 0. The seeds' common variation (an easy draw is easy for every
law) cancels in d_k, so a small advantage held on every seed separates where the two laws' own intervals overlap.
Identical values (two copies of one law) give d = 0 with no spread: never separable. A constant nonzero difference
(no spread, mean ≠ 0) is separable. Fewer than two paired seeds say nothing of the spread: not separable.

Paired t, not a paired bootstrap: it is the same Student-t interval as every other interval on the card; with the
suite's 3 to 10 seeds it is exact when the differences are normal, where a bootstrap's percentile interval is too
narrow (it takes the spread of a few seeds as known, with no t allowance, so its coverage falls short of 95 %), and
it needs no random draws, so a card re-ranks the same wherever it is read.

A law's rank is 1 + the number of laws separably better than it (paired_ranks): two copies of one law always share a
rank, and a law is ranked below another only when the two are separable. The rule is not a grouping: A may tie with
B and with C while B and C are separable, so A can share B's rank and still differ from C's. `ranks` and `separable`
keep the older rule over independent intervals (two laws separable when their intervals do not overlap), for
figures that are not paired by seed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

CONFIDENCE = 0.95  # the two-sided confidence of every interval on the card
RANKING = f"paired t, {100 * CONFIDENCE:g} %"  # the card's rank rule (paired_ranks), as the card names it


@dataclass(frozen=True)
class Estimate:
    """mean, and the interval [lo, hi] at CONFIDENCE over n finite values (lo = hi = mean when the values
    are all equal; ±inf with a single value: one seed says nothing of the spread)."""

    mean: float
    lo: float
    hi: float
    n: int

    def as_dict(self) -> dict:
        """As JSON allows it: a value that is not finite as null (from_dict reads it back)."""
        def num(v: float) -> float | None:
            return v if math.isfinite(v) else None

        return {"mean": num(self.mean), "lo": num(self.lo), "hi": num(self.hi), "n": self.n}

    @classmethod
    def from_dict(cls, d: dict) -> "Estimate":
        """The estimate of as_dict's dict (null: NaN for the mean, ∓inf for an open interval's ends)."""
        def num(v, missing: float) -> float:
            return missing if v is None else float(v)

        return cls(num(d["mean"], math.nan), num(d["lo"], -math.inf), num(d["hi"], math.inf), int(d["n"]))

    def text(self, fmt: str = ".3g") -> str:
        """"mean [lo, hi]" (or "n/a" when no seed gave a value)."""
        if self.n == 0 or not math.isfinite(self.mean):
            return "n/a"
        if self.lo == self.hi:
            return f"{self.mean:{fmt}}"
        return f"{self.mean:{fmt}} [{self.lo:{fmt}}, {self.hi:{fmt}}]"


def t_quantile(p: float, dof: int) -> float:
    """The p-quantile of Student's t with `dof` degrees of freedom (scipy.stats, which dm-control brings)."""
    from scipy.stats import t

    return float(t.ppf(p, dof))


def estimate(values: Sequence[float], *, lowest: float = -math.inf, highest: float = math.inf) -> Estimate:
    """The mean of the finite values and its t interval at CONFIDENCE (see the module docstring), the interval
    clipped to the figure's domain [lowest, highest] (a tail error is >= 0, a score within [0, 1]). NaN and ±inf
    (a run that gave no value) are left out: n says how many seeds the figure rests on."""
    x = np.array([float(v) for v in values if math.isfinite(v)], dtype=np.float64)
    if x.size == 0:
        return Estimate(math.nan, math.nan, math.nan, 0)
    mean = float(np.mean(x))
    if x.size == 1:
        return Estimate(mean, lowest, highest, 1)
    sd = float(np.std(x, ddof=1))
    if sd == 0.0:
        return Estimate(mean, mean, mean, int(x.size))
    half = t_quantile(0.5 + CONFIDENCE / 2, x.size - 1) * sd / math.sqrt(x.size)
    return Estimate(mean, max(lowest, mean - half), min(highest, mean + half), int(x.size))


def separable(a: Estimate, b: Estimate) -> bool:
    """Whether the two independent intervals do not overlap (the unpaired rule; the card pairs by seed: differs)."""
    return a.hi < b.lo or b.hi < a.lo


def ranks(estimates: Sequence[Estimate], *, higher_is_better: bool = True) -> list[int]:
    """Each estimate's rank by the unpaired rule: 1 + how many others are separable (`separable`) and better; an
    estimate with no value ranks last (the card ranks by paired_ranks)."""
    out = []
    for a in estimates:
        if a.n == 0:
            out.append(len(estimates))
            continue
        better = sum(1 for b in estimates if b.n and separable(a, b) and ((b.lo > a.hi) if higher_is_better
                                                                           else (b.hi < a.lo)))
        out.append(1 + better)
    return out


def paired_difference(a: Sequence[float], b: Sequence[float]) -> Estimate:
    """The mean of a_k − b_k over the seeds where both are finite and its paired t interval at CONFIDENCE (see the
    module docstring; not clipped). a, b: (n_seeds,) one figure of two laws on the same seeds in the same order; n
    says how many seeds the pair rests on."""
    if len(a) != len(b):
        raise ValueError(f"a paired comparison needs the same seeds for both laws, got {len(a)} and {len(b)} values")
    return estimate([x - y for x, y in zip(a, b, strict=True) if math.isfinite(x) and math.isfinite(y)])


def differs(d: Estimate) -> bool:
    """Whether a paired difference (paired_difference) is separable from 0: two or more seeds, and its interval
    excludes 0 (a constant nonzero difference has no width and does; a zero one does not)."""
    return d.n >= 2 and (d.lo > 0.0 or d.hi < 0.0)


def paired_ranks(values_by_law: Sequence[Sequence[float]], *, higher_is_better: bool = True) -> list[int]:
    """Each law's rank, in the order given: 1 + how many laws are separably better by their paired difference
    (see the module docstring); a law with no finite value ranks last. values_by_law: one (n_seeds,) sequence per
    law, every law's over the same seeds in the same order (NaN: no value on that seed)."""
    n_laws = len(values_by_law)
    has = [any(math.isfinite(v) for v in vals) for vals in values_by_law]
    out = []
    for i, a in enumerate(values_by_law):
        if not has[i]:
            out.append(n_laws)
            continue
        better = 0
        for j, b in enumerate(values_by_law):
            if j == i or not has[j]:
                continue
            d = paired_difference(b, a)  # > 0: b higher than a
            if differs(d) and ((d.lo > 0.0) if higher_is_better else (d.hi < 0.0)):
                better += 1
        out.append(1 + better)
    return out


def separated_pairs(values_by_law: Sequence[Sequence[float]]) -> int:
    """How many of the len·(len − 1)/2 pairs of laws are separable by their paired difference."""
    return sum(1 for i in range(len(values_by_law)) for j in range(i + 1, len(values_by_law))
               if differs(paired_difference(values_by_law[i], values_by_law[j])))


def cvar(values: Sequence[float], level: float = 0.10) -> float:
    """The mean of the worst (largest) ⌈level·n⌉ values: with 5 seeds at 10 %, the worst one."""
    x = np.sort(np.asarray(values, dtype=float))[::-1]
    if x.size == 0:
        return math.nan
    return float(np.mean(x[:max(1, math.ceil(level * x.size))]))
