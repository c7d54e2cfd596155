"""The camera view rebuilt from the totem rays: its colour and its depth.

`sweep` is plane-sweep stereo between the totems; `splat` puts the totem rays' colours on
the camera view at a depth map; `support` is the plane resting totems stand on; `view`
renders the grid's view and chooses, pixel by pixel, between it and stereo's.

May import: inverse, scenes.
"""
