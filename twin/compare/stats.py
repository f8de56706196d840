"""The statistics of a comparison, apart from what they are applied to: one interval method per kind of
quantity, and paired tests (Wilcoxon signed-rank on paired values, an exact sign test on paired outcomes).

Why these:
- a success rate (k successes of n runs) gets the Wilson score interval (`wilson_ci`), wherever it is
  shown: summary tables, summary.csv, sweep tables, plots. A comparison has few runs per planner and
  scenario (2 to 30), and the bootstrap of a proportion cannot see beyond its sample: 2/2 gives
  [100 %, 100 %], 2/4 gives [0 %, 100 %]. Wilson's interval stays inside [0, 1], does not collapse at 0/n
  or n/n (2/2 gives [34 %, 100 %], 3/3 [44 %, 100 %]) and keeps close to its nominal 95 % coverage for
  small n (Brown, Cai & DasGupta 2001), where Clopper-Pearson is conservative (wider than it needs be).
- a median (planning time, duration, any continuous metric) gets a percentile bootstrap interval
  (`bootstrap_ci`, `scipy.stats.bootstrap`, vectorised, seeded: the same values give the same interval),
  because those values are skewed and far from normal. It needs two values: one value has no spread to
  resample, so it gets no interval. With few values it is narrow for what it knows, so n is printed
  beside every median.
- paired differences are tested by rank (Wilcoxon), not by a t-test; paired successes by an exact
  binomial test on the pairs where only one side succeeded (McNemar's exact form).

`INTERVALS` is the sentence every report prints to say so.
"""

from __future__ import annotations

import functools
import inspect
import math
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np

__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "CONFIDENCE",
    "INTERVALS",
    "MIN_DISCORDANT",
    "SIGNIFICANCE",
    "PairedTest",
    "bootstrap_ci",
    "is_tie",
    "sign_test",
    "signed_rank",
    "stable_seed",
    "wilson_ci",
]

CONFIDENCE = 0.95  # of every interval
SIGNIFICANCE = 0.05  # a paired test's p below this calls a difference real (report's verdicts)
BOOTSTRAP_RESAMPLES = 2000
MIN_DISCORDANT = 6  # fewer non-tied pairs give no p: with 5, the smallest exact two-sided p is 2/2^5 > 0.05
TIE_ABS, TIE_REL = 1e-9, 1e-6  # see is_tie
INTERVALS = (
    f"Intervals: success rates: {100 * CONFIDENCE:.0f} % Wilson score intervals; medians: "
    f"{100 * CONFIDENCE:.0f} % percentile bootstrap ({BOOTSTRAP_RESAMPLES} resamples), over the n runs shown "
    "beside each (one run: no interval)."
)


@overload
def is_tie(a: float, b: float) -> bool: ...
@overload
def is_tie(a: np.ndarray, b: np.ndarray) -> np.ndarray: ...
def is_tie(a: float | np.ndarray, b: float | np.ndarray) -> bool | np.ndarray:
    """Whether paired values count as equal: |a - b| <= 1e-9 + 1e-6 * max(|a|, |b|) (elementwise on arrays).

    Equal values are always ties; so are differences below a part per million (or a nanosecond for
    values in seconds), which no timer or retimer resolves and no user would call a win.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    tie = np.abs(a - b) <= TIE_ABS + TIE_REL * np.maximum(np.abs(a), np.abs(b))
    return bool(tie) if tie.ndim == 0 else tie


def stable_seed(*parts: str) -> int:
    """A seed that depends on the parts only (crc32 is stable across runs, unlike hash())."""
    return zlib.crc32("\x1f".join(parts).encode("utf-8"))


def wilson_ci(successes: int, n: int, *, confidence: float = CONFIDENCE) -> tuple[float, float] | None:
    """The Wilson score interval of a success rate `successes / n` (None for n = 0), the one interval of a
    proportion in every report: unlike the bootstrap or the normal approximation it stays inside [0, 1] and
    does not shrink to a point at 0/n or n/n, so it is honest for few runs (Wilson 1927; Brown, Cai &
    DasGupta 2001)."""
    if n <= 0:
        return None
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be in 0..n, got {successes} of {n}")
    from scipy.stats import norm

    z = float(norm.ppf(0.5 + confidence / 2))
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    # at 0/n and n/n the bound on that side is exactly 0 or 1 (rounding would leave 1e-17 off)
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return lo, hi


@functools.cache
def _bootstrap() -> tuple[Callable[..., Any], str]:
    """scipy.stats.bootstrap and the name of its generator argument (`rng` since scipy 1.15)."""
    from scipy.stats import bootstrap

    return bootstrap, "rng" if "rng" in inspect.signature(bootstrap).parameters else "random_state"


def bootstrap_ci(
    values: Sequence[float] | np.ndarray,
    *,
    seed: int,
    resamples: int = BOOTSTRAP_RESAMPLES,
    confidence: float = CONFIDENCE,
) -> tuple[float, float] | None:
    """The percentile-bootstrap interval of the median of continuous `values` (a proportion's interval is
    `wilson_ci`): None for fewer than two values (one value has nothing to resample, and [v, v] would claim
    a certainty it does not have), [v, v] when all are equal; otherwise `resamples` resamples drawn by
    numpy's Generator seeded with `seed`, all at once (scipy.stats.bootstrap, vectorised), so the same
    values and seed give the same interval."""
    a = np.asarray(values, dtype=float)
    if a.size < 2:
        return None
    if bool(np.all(a == a[0])):
        return float(a[0]), float(a[0])
    bootstrap, rng_kw = _bootstrap()
    res = bootstrap(
        (a,),
        np.median,
        n_resamples=resamples,
        vectorized=True,
        method="percentile",
        confidence_level=confidence,
        **{rng_kw: np.random.default_rng(seed)},
    )
    ci = res.confidence_interval
    return float(ci.low), float(ci.high)


@dataclass(frozen=True)
class PairedTest:
    """Pairs (a, b) compared: a wins where it is better, ties by `is_tie`; median of a - b; p or None."""

    wins: int
    ties: int
    losses: int
    median_diff: float
    p_value: float | None


def signed_rank(a: np.ndarray, b: np.ndarray, *, higher_is_better: bool = False) -> PairedTest:
    """Wins, ties and losses of `a` against `b` (paired, same length), the median of a - b, and the
    two-sided Wilcoxon signed-rank p on the non-tied pairs (zero_method "wilcox": ties are set aside
    and reported as ties); p is None below MIN_DISCORDANT non-tied pairs."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    d = a - b
    tie = is_tie(a, b)
    better = d > 0 if higher_is_better else d < 0
    wins, ties = int(np.sum(~tie & better)), int(np.sum(tie))
    losses = int(d.size) - wins - ties
    p = None
    if wins + losses >= MIN_DISCORDANT:
        from scipy.stats import wilcoxon

        res = wilcoxon(d[~tie], zero_method="wilcox", alternative="two-sided", method="auto")
        p = float(res.pvalue) if math.isfinite(res.pvalue) else None
    return PairedTest(wins, ties, losses, float(np.median(d)), p)


def sign_test(wins: int, losses: int) -> float | None:
    """Two-sided exact binomial p of `wins` against `losses` (discordant pairs); None below MIN_DISCORDANT."""
    if wins + losses < MIN_DISCORDANT:
        return None
    from scipy.stats import binomtest

    return float(binomtest(wins, wins + losses, 0.5, alternative="two-sided").pvalue)
