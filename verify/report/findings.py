"""The values of one photo's verification (:class:`Report`) and report.json's fields.

:func:`verify.report.report.verify_scene` makes a Report;
:func:`verify.report.report.write_verify` writes it as files (report.json from
:meth:`Report.to_json`, report.html by
:mod:`verify.report.html_report`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from verify.metrics import agreement, evidence, patches
from verify.verdict import verdict as verdict_mod

__all__ = ["Report"]


@dataclass
class Report:
    """Everything ``totems verify`` found; ``to_json`` gives report.json.

    Arrays: ``protected`` (H, W) bool; ``recon``, ``image`` (H, W, 3) sRGB [0, 1];
    ``totem_mask`` (H, W) bool; ``heatmaps[name]`` (G, G) in heatmap.npy units (see
    :mod:`verify.metrics.patches`); ``keep`` (G, G) patches overlapping the protected
    region; ``silhouettes`` (n, H, W) bool, each fitted sphere's image (the outlines
    report.html draws; None when unknown). ``scene_name``: the scene folder's name, for
    report.html. Neither is in report.json. ``judged`` (H, W) bool, the pixels RANGE and
    UNSEEN judge (the protected region where the evidence map resolves the surface; written
    as judged_mask.png) and ``judged_fraction`` its share of the non-totem pixels (in
    report.json); ``evidence`` the :class:`verify.metrics.evidence.Evidence` map (None for a
    fit without totem rays); ``tone`` the gains that brought ``recon`` (the view compared)
    to the photo's exposure (:func:`verify.metrics.tone.match_gain`); ``holdout`` the fit's
    leave-one-totem-out error the verdict tests (:data:`verify.verdict.verdict.MAX_HOLDOUT`;
    None for a fit without it). ``judging`` the verdict's patch grid over the whole photo
    (:func:`verify.verdict.verdict.judging_grid`; the drivers' ``row`` and ``col`` index
    it), ``grid`` the heatmaps' above the totems. ``agreement`` the totems checked
    against each other (:class:`verify.metrics.agreement.Agreement`; None for a fit
    without totem rays): report.json's ``totem_check``.
    """

    verdict: str
    score: float
    threshold: float
    protected: np.ndarray
    protected_fraction: float
    recon: np.ndarray
    image: np.ndarray
    totem_mask: np.ndarray
    grid: patches.PatchGrid
    heatmaps: dict
    keep: np.ndarray
    decision: verdict_mod.Verdict
    totems: list
    metrics: dict
    key_fingerprint: str
    region: str = "filled"
    timing_s: dict = field(default_factory=dict)
    versions: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)
    silhouettes: np.ndarray | None = None
    scene_name: str = ""
    scale: int = 1
    judged: np.ndarray | None = None
    judged_fraction: float | None = None
    evidence: object = None
    tone: dict | None = None
    judging: patches.PatchGrid | None = None
    holdout: float | None = None
    agreement: agreement.Agreement | None = None

    @property
    def drivers(self) -> list:
        return self.decision.drivers

    def to_json(self) -> dict:
        """report.json: the contract's fields plus ``scores`` (each metric's own score,
        threshold and median patch; ``score`` is the largest score / threshold),
        ``statistic``, ``p_value`` and ``line_p_value`` (the calibration's,
        :mod:`verify.verdict.calibration`), ``drivers``, ``key_fingerprint``, ``region``
        (the protected region's shape), ``working_scale`` (:mod:`scenes.working`),
        ``judged_fraction`` and ``evidence`` (:mod:`verify.metrics.evidence`), ``tone``
        (:mod:`verify.metrics.tone`), ``holdout``, ``unverifiable_reason`` and
        ``inconsistent_reasons`` (:func:`verify.verdict.verdict.decide`), ``totem_check``
        (:meth:`totem_check`) and a
        ``metrics.patch_ap_<name>`` for every heatmap (docs/contract.md)."""
        return {
            "verdict": self.verdict,
            "score": _num(self.score),
            "threshold": _num(self.threshold),
            "protected_fraction": _num(self.protected_fraction),
            "totems": self.totems,
            "metrics": {k: _num(v) for k, v in self.metrics.items()},
            "timing_s": {k: _num(v) for k, v in self.timing_s.items()},
            "versions": self.versions,
            "scores": {m: {"score": _num(v), "threshold": _num(self.decision.thresholds[m]),
                           "median": _num(self.decision.medians[m])}
                       for m, v in self.decision.scores.items()},
            "statistic": _num(self.decision.statistic),
            "p_value": _p(self.decision.p_value),
            "line_p_value": _p(self.decision.line_p_value),
            "skipped": self.skipped,
            "drivers": self.drivers,
            "key_fingerprint": self.key_fingerprint,
            "region": self.region,
            "working_scale": int(self.scale),
            "judged_fraction": _num(self.judged_fraction),
            "evidence": None if self.evidence is None else {
                "min_totems": int(evidence.MIN_TOTEMS),
                "min_parallax": float(evidence.MIN_PARALLAX),
                "resolved_fraction": _num(float(self.evidence.resolved.mean())),
                "min_judged": float(verdict_mod.MIN_JUDGED)},
            "holdout": {"L1": _num(self.holdout),
                        "max": float(verdict_mod.MAX_HOLDOUT)},
            "unverifiable_reason": self.decision.reason,
            "inconsistent_reasons": list(self.decision.inconsistent_reasons),
            "totem_check": self.totem_check(),
            "tone": None if self.tone is None else {
                "gain": [_num(g) for g in self.tone["gain"]],
                "pixels": int(self.tone["pixels"])},
        }

    def totem_check(self) -> dict | None:
        """report.json's ``totem_check``: the line, the totems named, and per totem (left
        to right) its worst region's ``score`` and ``lead`` (discord units), where that
        region lies (``centre_px`` [u, v] and ``radius_px`` in the photo's pixels; null
        where nothing of the totem was predicted) and the share of its pixels ``judged``;
        None without totem rays."""
        a = self.agreement
        if a is None:
            return None
        named = set(self.decision.totems_named)
        totems = []
        for j in range(len(a.score)):
            where = None if not np.isfinite(a.score[j]) else {
                "centre_px": [round(float(a.centre[j, 0]), 1),
                              round(float(a.centre[j, 1]), 1)],
                "radius_px": round(float(a.radius[j]), 1)}
            totems.append({"totem": j, "named": j in named, "score": _num(a.score[j]),
                           "lead": _num(a.lead[j]), "judged": _num(a.judged[j]),
                           "where": where})
        return {"line": float(verdict_mod.TOTEM_LEAD),
                "min_others": int(agreement.MIN_OTHERS),
                "named": sorted(named), "totems": totems}


def _p(x):
    return None if x is None else float(f"{x:.4g}")


def _num(x):
    return None if x is None or not np.isfinite(x) else round(float(x), 6)
