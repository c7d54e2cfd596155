"""Compare the camera view rebuilt from the totems with the photo: metrics, verdict, report.

No module here: `metrics` (the heatmaps, the tests that read the totem rays, the evidence
map, the protected region), `verdict` (the image-level word and its calibration), `report`
(report.json, report.html, the NeRF cross-check), `batch` (many photos on Dask's
scheduler, `bench`) and `cli` (the `totems` command, thin on top), each importing only the
rooms below it.

May import: inverse, scenes; each subpackage says its own.
"""
