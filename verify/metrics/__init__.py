"""What the photo and the totems say at each pixel: heatmaps, ray tests, evidence.

`patches` compares the photo with the rebuilt view patch by patch (L1, SSIM, RANGE,
CHROMA); `corroborate` (CORROB, UNSEEN) and `absence` (ABSENT) read the totem rays
themselves; `agreement` checks the totems against each other (each totem's view
predicted from the others'); `evidence` says what the totems establish at each pixel,
`resolution` how
finely, `region` which part of the view is protected; `tone` brings the view to the
photo's exposure first; `truth` reads a synthetic scene's truth (the true view, pose,
depth and reach) for the metrics, never for the verdict.

May import: inverse, inverse.view, scenes.
"""
