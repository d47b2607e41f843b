"""Distribution-free statistics of campaign flights (docs/SCOREBOARD.md): a quantile of the RMSE with its
order-statistic interval, and the paired comparison of two controllers over the same perturbed flights.

A failed flight (it did not finish: non-finite state, flipped, crashed, too far from the reference) has
no RMSE; here it counts as an RMSE of +inf, worse than any finished flight. So a percentile that falls
on failed flights is +inf ("failed"), a controller that fails where the other finishes loses that pair,
and two failures are a tie.

Intervals (95 % unless stated): for the q-quantile of n values x_(1) <= ... <= x_(n), the interval
[x_(l), x_(u)] with l, u the ranks around n q whose binomial probabilities leave at most 2.5 % on each
side: P(l <= B <= u - 1) >= 95 % with B ~ Binomial(n, q) (the sign test's interval when q = 1/2; e.g.
Conover, *Practical Nonparametric Statistics*, 3rd ed., sec. 3.2). It assumes only that the values are
independent draws (the flights of a seed are), nothing about their distribution.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

CONFIDENCE = 0.95


def binomial_cdfs(n: int, p: float) -> list[float]:
    """[P(B <= k) for k = 0..n], B ~ Binomial(n, p): the probabilities in log space, then summed."""
    if p <= 0.0 or p >= 1.0:
        return [1.0 if p <= 0.0 or k == n else 0.0 for k in range(n + 1)]
    log_p, log_q, log_n = math.log(p), math.log1p(-p), math.lgamma(n + 1)
    cdfs, total = [], 0.0
    for k in range(n + 1):
        total += math.exp(log_n - math.lgamma(k + 1) - math.lgamma(n - k + 1) + k * log_p + (n - k) * log_q)
        cdfs.append(min(1.0, total))
    return cdfs


def quantile_ranks(n: int, q: float, confidence: float = CONFIDENCE) -> tuple[int | None, int | None]:
    """(l, u), 1-based ranks with P(l <= B <= u - 1) >= ``confidence``, B ~ Binomial(n, q), each tail at
    most (1 - confidence) / 2; None where no rank is far enough out (too few values: the interval is
    unbounded on that side)."""
    if not 0.0 < q < 1.0:
        raise ValueError(f'quantile_ranks: q = {q} must lie in (0, 1)')
    if not 0.0 < confidence < 1.0:
        raise ValueError(f'quantile_ranks: confidence = {confidence} must lie in (0, 1)')
    tail = 0.5 * (1.0 - confidence)
    cdf = binomial_cdfs(n, q)     # cdf[k] = P(B <= k)
    lower = [r for r in range(1, n + 1) if cdf[r - 1] <= tail]         # P(B < l) = cdf[l - 1]
    upper = [r for r in range(1, n + 1) if 1.0 - cdf[r - 1] <= tail]   # P(B >= u) = 1 - cdf[u - 1]
    return (max(lower) if lower else None), (min(upper) if upper else None)


@dataclass(frozen=True)
class Quantile:
    """A sample quantile with its distribution-free interval: an end is nan where too few values give one
    (no rank leaves at most 2.5 % beyond it), +inf where it falls on failures."""

    q: float
    value: float
    low: float
    high: float
    n: int


def quantile(values: Sequence[float], q: float, confidence: float = CONFIDENCE) -> Quantile:
    """The q-quantile of ``values`` (the order statistic of rank ceil(n q); +inf allowed) and its interval."""
    ordered = sorted(float(v) for v in values)
    n = len(ordered)
    if n == 0:
        raise ValueError('quantile: no value')
    if any(math.isnan(v) for v in ordered):
        raise ValueError('quantile: a value is nan (count a failed flight as +inf)')
    l, u = quantile_ranks(n, q, confidence)
    value = ordered[max(1, math.ceil(n * q)) - 1]
    return Quantile(q, value, ordered[l - 1] if l else math.nan, ordered[u - 1] if u else math.nan, n)


def rmse_or_failed(row: dict) -> float:
    """A flight's position RMSE [m]; +inf for a flight that did not finish."""
    return float(row['rmse_position_m']) if row['finished'] else math.inf


@dataclass(frozen=True)
class Paired:
    """``kind`` against ``reference`` over the same flights (module docstring: failures count as +inf)."""

    pairs: int
    kind_better: int          #: flights where ``kind`` has the lower RMSE (or finished where the other failed)
    reference_better: int
    ties: int                 #: equal RMSE, or both failed
    median_difference: Quantile   #: of RMSE(kind) - RMSE(reference) [m] (+-inf where one failed)
    sign_test_p: float        #: two-sided sign test of kind_better against reference_better (ties left out)

    @property
    def kind_better_share(self) -> float:
        return self.kind_better / self.pairs

    @property
    def reference_better_share(self) -> float:
        return self.reference_better / self.pairs


def difference(kind: float, reference: float) -> float:
    """RMSE(kind) - RMSE(reference) with +inf for a failure: +inf or -inf where one failed, 0 where both did."""
    if math.isinf(kind) and math.isinf(reference):
        return 0.0
    return kind - reference


def paired(kind_rows: Sequence[dict], reference_rows: Sequence[dict], confidence: float = CONFIDENCE) -> Paired:
    """Compare two controllers' flights.csv rows of one campaign seed, paired by flight index.

    ValueError if the two do not hold the same flights (a pair needs both)."""
    mine = {row['flight']: rmse_or_failed(row) for row in kind_rows}
    theirs = {row['flight']: rmse_or_failed(row) for row in reference_rows}
    if set(mine) != set(theirs):
        missing = sorted(set(mine) ^ set(theirs))
        raise ValueError(f'paired: the two controllers flew different flights (e.g. flight {missing[0]} of only one)')
    if not mine:
        raise ValueError('paired: no flight')
    differences = [difference(mine[k], theirs[k]) for k in sorted(mine)]
    better = sum(1 for d in differences if d < 0.0)
    worse = sum(1 for d in differences if d > 0.0)
    return Paired(len(differences), better, worse, len(differences) - better - worse,
                  quantile(differences, 0.5, confidence), sign_test(better, worse))


def sign_test(wins: int, losses: int) -> float:
    """Two-sided p-value of ``wins`` against ``losses`` under a fair coin (1.0 without any)."""
    n = wins + losses
    if n == 0:
        return 1.0
    return min(1.0, 2.0 * binomial_cdfs(n, 0.5)[min(wins, losses)])
