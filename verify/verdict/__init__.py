"""The image-level verdict: consistent, inconsistent or unverifiable, and its calibration.

`verdict` turns the metrics' scores into the word and the patches that drove it;
`calibration` turns the statistic into a p-value from untouched photos
(`calibration.json`, shipped beside it).

May import: verify.metrics, scenes.
"""
