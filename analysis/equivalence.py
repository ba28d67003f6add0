"""Evidence for a null beside the primary test: its confidence interval, an equivalence test
against the study's smallest effect of interest, and a default Bayes factor.

A primary test that is not significant says the study found no difference, not that there is
none. Three numbers say which it is:

- **95% CI** of the mean difference with participants and trials random: mean +- t(0.975, df)
  SE, with SE and df from analysis/crossed.py `crossed_standard_error` (the SE whose square
  min F' divides the squared mean by, on min F's df).
- **TOST** (two one-sided tests; Schuirmann 1987, J Pharmacokinet Biopharm 15:657-680;
  Lakens 2017, Soc Psychol Personal Sci 8:355-362): is the difference above -SESOI and below
  +SESOI? p is the larger of the two one-sided t-tests' p, each on the same SE and df as the
  primary test, so it treats both random factors the way min F' does and is no more liberal
  than it: equivalence at alpha is the (1 - 2 alpha) CI lying within +-SESOI. The SESOI is the
  study config's `smallest_effect_of_interest`, fixed before any data.
- **BF10**, the JZS Bayes factor of the paired difference (Rouder, Speckman, Sun, Morey &
  Iverson 2009, Psychon Bull Rev 16:225-237, eq. 1; Cauchy prior on the standardised effect,
  scale r = sqrt(2)/2) on the participants' mean differences: BF10 < 1/3 is evidence for no
  difference, > 3 for one. It treats participants as random only, as a default reading beside
  the two tests above, which decide the conclusion.

The conclusion per world: the primary verdict (`ours`, `vae`) where the primary test is
significant, else `equivalent` where TOST's p is below alpha, else `inconclusive`.
"""

import numpy as np
from scipy import integrate, stats

CAUCHY_SCALE = float(np.sqrt(2) / 2)  # Rouder et al. 2009's "medium" prior scale
EQUIVALENT = "equivalent"
INCONCLUSIVE = "inconclusive"


def t_interval(mean: float, se: float, df: float, level: float = 0.95) -> tuple[float, float]:
    """mean +- t(level, df) se (NaN where se or df is undefined)."""
    if not (np.isfinite(se) and np.isfinite(df) and df > 0):
        return float("nan"), float("nan")
    half = float(stats.t.ppf(0.5 + level / 2, df)) * se
    return mean - half, mean + half


def tost_p(mean: float, se: float, df: float, bound: float) -> float:
    """The TOST p that the true difference lies within +-bound: the larger one-sided p."""
    if not (np.isfinite(se) and np.isfinite(df) and df > 0):
        return float("nan")
    with np.errstate(divide="ignore", invalid="ignore"):
        above = np.float64(mean + bound) / se  # H0: difference <= -bound
        below = np.float64(mean - bound) / se  # H0: difference >= +bound
    p = max(stats.t.sf(above, df), stats.t.cdf(below, df))
    return float(p)


def jzs_bf10(t: float, n: int, r: float = CAUCHY_SCALE) -> float:
    """BF10 of a one-sample (or paired) t-test of n values: Rouder et al. 2009 eq. 1."""
    if n < 2 or not np.isfinite(t):
        return float("nan")
    df = n - 1
    null_log = np.log1p(t * t / df)

    def integrand(g: float) -> float:
        spread = 1 + n * g * r * r
        log_ratio = (-0.5 * np.log(spread)
                     - (df + 1) / 2 * (np.log1p(t * t / (spread * df)) - null_log))
        # g ~ InverseGamma(1/2, 1/2) makes the normal prior on the effect a Cauchy(0, r)
        return float(np.exp(log_ratio + stats.invgamma.logpdf(g, 0.5, scale=0.5)))

    # split where the prior's mass is, so quad sees the peak on a finite interval
    low = integrate.quad(integrand, 0, 1, limit=200)[0]
    high = integrate.quad(integrand, 1, np.inf, limit=200)[0]
    return low + high


def paired_bf10(differences, r: float = CAUCHY_SCALE) -> float:
    """JZS BF10 that the mean of the paired differences is not 0 (NaN below 2 values or
    without spread)."""
    values = np.asarray(differences, dtype=np.float64)
    if len(values) < 2 or not np.ptp(values) > 0:
        return float("nan")
    return jzs_bf10(float(stats.ttest_1samp(values, 0.0).statistic), len(values), r)


def conclusion(verdict: str, tost: float, alpha: float) -> str:
    """The primary verdict where it names a model, else equivalent or inconclusive."""
    if verdict != "neither":
        return verdict
    return EQUIVALENT if tost < alpha else INCONCLUSIVE
