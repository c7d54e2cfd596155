"""The joint fit: the frustum radiance grid and the totem centres, fitted to the totem
pixels.

`fit` runs it (`fit_scene`: pose, rays, optimisation, pose check, the camera view);
`batches` feeds each step its rays, `losses` and `outline` are its terms; `files` is what
a fit gives (`FitResult`) and its folder `fit/`.

May import: inverse, inverse.pose, inverse.view, scenes.
"""
