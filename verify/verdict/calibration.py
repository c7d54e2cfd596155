"""The verdict's statistic calibrated on untouched photos: a p-value per photo.

The statistic ``T`` is the verdict's raw score (:func:`verify.verdict.verdict.decide`): the
largest of the metrics' scores, each in units of its scale (``verdict.SCALES``). Over
untouched photos ``T`` has some distribution; the p-value of a photo is the chance that
an untouched photo scores at least its ``T``, a false-alarm probability:

    p(t) = (#{T_i >= t} + 1) / (n + 1)                        for t <= u
    p(t) = (k + 1) / (n + 1) * (1 + xi (t - u) / sigma)^(-1/xi)  for t > u

with ``T_1..T_n`` the calibration set's untouched statistics, ``u`` the start of the
tail (the ``n - k``-th smallest, ``k = ceil(TAIL_FRACTION n)``) and a generalised
Pareto tail (``xi``, ``sigma``) fitted to the ``k`` excesses over ``u`` by maximum
likelihood (peaks over threshold), so that p-values below the ``1 / (n + 1)`` a rank
allows are estimated rather than clipped. ``xi`` is kept >= 0: no bounded tail is
claimed from a few dozen photos. ``line(ALPHA)`` is the statistic where ``p = ALPHA``;
the verdict reports p beside its own fixed line and does not decide by it (see
docs/decisions.md, 'verdict: p-values reported, the line kept').

The calibration the package ships (``calibration.json`` beside this module) is written
by ``benchmarks/calibrate_verdict.py`` from a bench of the calibration set
(``benchmarks/sets.py``); a photo with fewer totems than a metric needs (ABSENT: three)
is judged on fewer metrics, so its ``T`` is a maximum over fewer terms and the shipped
p-value is conservative for it.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from scenes.errors import BadInput

__all__ = ["ALPHA", "TAIL_FRACTION", "SHIPPED", "Calibration", "fit_tail", "load",
           "statistic_of", "clopper_pearson", "leave_one_group_out", "line_without"]

ALPHA = 0.01
"""The per-photo false-alarm rate a calibrated line is computed for (benchmarks)."""

TAIL_FRACTION = 0.3
"""Share of the calibration photos whose excesses the tail model is fitted to."""

SHIPPED = Path(__file__).with_name("calibration.json")


@dataclass(frozen=True)
class Calibration:
    """Untouched statistics (sorted) and the tail fitted to their largest ones.

    ``u`` start of the tail, ``k`` photos above it, ``xi`` (>= 0) and ``sigma`` the
    generalised Pareto shape and scale of their excesses (statistic units);
    ``source`` says what it was fitted on (set, photos, channels, code version).
    """

    statistics: tuple
    u: float
    k: int
    xi: float
    sigma: float
    alpha: float = ALPHA
    source: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.statistics)

    def p_value(self, t: float) -> float:
        """The chance an untouched photo scores at least ``t``."""
        t = float(t)
        if not math.isfinite(t):
            raise BadInput(f"the verdict's statistic is not a number ({t})")
        if t <= self.u:
            ge = int(np.sum(np.asarray(self.statistics) >= t))
            return (ge + 1) / (self.n + 1)
        z = (t - self.u) / self.sigma
        tail = math.exp(-z) if self.xi < 1e-9 else (1.0 + self.xi * z) ** (-1.0 / self.xi)
        return (self.k + 1) / (self.n + 1) * tail

    def line(self, alpha: float | None = None) -> float:
        """The statistic at which the p-value falls to ``alpha`` (default ``ALPHA``)."""
        alpha = self.alpha if alpha is None else float(alpha)
        head = (self.k + 1) / (self.n + 1)
        if alpha >= head:        # inside the empirical part: the smallest statistic
            above = [x for x in self.statistics if self.p_value(x) < alpha]
            return float(min(above)) if above else float(max(self.statistics))
        q = alpha / head
        z = -math.log(q) if self.xi < 1e-9 else (q ** (-self.xi) - 1.0) / self.xi
        return self.u + self.sigma * z

    def to_json(self) -> dict:
        d = asdict(self)
        d["statistics"] = [round(float(x), 6) for x in self.statistics]
        return d

    @classmethod
    def from_json(cls, d: dict) -> "Calibration":
        return cls(statistics=tuple(float(x) for x in d["statistics"]), u=float(d["u"]),
                   k=int(d["k"]), xi=float(d["xi"]), sigma=float(d["sigma"]),
                   alpha=float(d.get("alpha", ALPHA)), source=dict(d.get("source", {})))


def fit_tail(statistics, *, tail_fraction: float = TAIL_FRACTION, alpha: float = ALPHA,
             source: dict | None = None) -> Calibration:
    """The :class:`Calibration` of untouched photos' statistics (at least 10)."""
    from scipy import stats

    t = np.sort(np.asarray(statistics, np.float64))
    if t.size < 10 or not np.all(np.isfinite(t)):
        raise BadInput(f"a calibration needs at least 10 finite statistics, got {t.size}")
    k = max(5, int(math.ceil(tail_fraction * t.size)))
    u = float(t[t.size - k - 1])
    excess = t[t.size - k:] - u
    xi, _, sigma = stats.genpareto.fit(excess, floc=0.0)
    if xi < 0.0:                         # no bounded tail: the exponential's MLE
        xi, sigma = 0.0, float(excess.mean())
    sigma = max(float(sigma), 1e-9)
    return Calibration(tuple(float(x) for x in t), u, k, float(xi), sigma, alpha,
                       dict(source or {}))


def load(path=None) -> Calibration:
    """The calibration in ``path`` (default: the one the package ships)."""
    path = SHIPPED if path is None else Path(path)
    try:
        return Calibration.from_json(json.loads(path.read_text()))
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise BadInput(f"cannot read the verdict's calibration {path}: {e}") from None


def statistic_of(report: dict) -> float | None:
    """The verdict's statistic of a report.json (or a bench run's summary); a report
    from before the calibration (neither ``statistic`` nor ``line``) had its line at 1,
    so its ``score`` is the statistic."""
    if "statistic" not in report and "line" not in report:
        return report.get("score")
    return report.get("statistic")


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Exact binomial interval for a rate of ``k`` events in ``n`` trials."""
    from scipy.stats import beta

    a = (1.0 - confidence) / 2.0
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - a, k + 1, n - k))
    return lo, hi


def leave_one_group_out(statistics, groups, *, alpha: float = ALPHA, **fit_kw) -> dict:
    """False alarms at ``alpha`` when each group (e.g. a preset) is held out: the tail
    fitted on the others, the held-out photos judged by it.

    Returns {group: (false alarms, photos)} and "all": (total, photos, (lo, hi)), the
    total's 95 % interval.
    """
    t = np.asarray(statistics, np.float64)
    g = np.asarray(groups)
    out = {}
    for name in sorted(set(g.tolist())):
        cal = fit_tail(t[g != name], alpha=alpha, **fit_kw)
        held = t[g == name]
        out[name] = (int(sum(cal.p_value(x) < alpha for x in held)), int(held.size))
    k = sum(v[0] for v in out.values())
    n = sum(v[1] for v in out.values())
    out["all"] = (k, n, clopper_pearson(k, n))
    return out


def line_without(statistics, groups, *, alpha: float, **fit_kw) -> dict:
    """Where the line at ``alpha`` falls when each group is left out of the fit: how
    far each group (e.g. a preset) pulls the line up.

    Returns {group: the line fitted on the other groups' statistics} and "all": the line
    fitted on every statistic (statistic units).
    """
    t = np.asarray(statistics, np.float64)
    g = np.asarray(groups)
    out = {name: fit_tail(t[g != name], **fit_kw).line(alpha)
           for name in sorted(set(g.tolist()))}
    out["all"] = fit_tail(t, **fit_kw).line(alpha)
    return out
