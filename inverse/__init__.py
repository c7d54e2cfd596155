"""Inverse rendering: the totems' pose, the joint fit of a radiance grid and the totem
centres with Dr.Jit gradients, and the camera view rebuilt from the fit (camera frame =
OpenCV, metres).

The modules here are the forward model every step shares: a glass sphere's ray optics
(`sphere`), the totem pixels as rays (`rays`), the frustum grid (`grid`), the Mitsuba
integrator that renders it (`integrator`) and its thread-independent gathers
(`exact_gather`). Then, in the order the data flows: `pose` (centres from the masks and
the photo), `view` (the camera view and its depth: stereo, splats, the support plane),
`fit` (the optimisation, which starts from `pose` and ends in `view`).

May import: scenes (the core); each subpackage says its own.
"""
