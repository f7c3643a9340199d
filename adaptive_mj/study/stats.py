"""Statistics over seeds for the scorecard: a mean with its Student-t confidence interval, and ranks that
say when two laws cannot be told apart at that confidence.

A figure measured on n seeds x_1..x_n is reported as mean ± t_{1-α/2, n-1} · s / √n (s the sample standard
deviation, α = 1 − CONFIDENCE). Two laws are *separable* on a figure when their intervals do not overlap.
A law's rank is 1 + the number of laws whose interval lies wholly on the better side of its own: two copies of one
law always share a rank, and a law is ranked below another only when the two are separable. The rule is not a
grouping: A may overlap B and C while B and C are separable, so A can share B's rank and still differ from C's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

CONFIDENCE = 0.95  # the two-sided confidence of every interval on the card


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
    """Whether the two intervals do not overlap (the figures differ at CONFIDENCE)."""
    return a.hi < b.lo or b.hi < a.lo


def ranks(estimates: Sequence[Estimate], *, higher_is_better: bool = True) -> list[int]:
    """Each estimate's rank: 1 + how many others are separably better (see the module docstring); an
    estimate with no value ranks last."""
    out = []
    for a in estimates:
        if a.n == 0:
            out.append(len(estimates))
            continue
        better = sum(1 for b in estimates if b.n and separable(a, b) and ((b.lo > a.hi) if higher_is_better
                                                                           else (b.hi < a.lo)))
        out.append(1 + better)
    return out


def cvar(values: Sequence[float], level: float = 0.10) -> float:
    """The mean of the worst (largest) ⌈level·n⌉ values: with 5 seeds at 10 %, the worst one."""
    x = np.sort(np.asarray(values, dtype=float))[::-1]
    if x.size == 0:
        return math.nan
    return float(np.mean(x[:max(1, math.ceil(level * x.size))]))
