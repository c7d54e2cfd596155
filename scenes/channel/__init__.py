"""The capture channel: what a camera, then a messenger, does to a photo.

`channel` is the model (blur, tone curve, noise, sharpening, JPEG, resize), as plain
functions on arrays; `recapture` puts a scene folder's photo through it
(`totems recapture`).

May import: scenes.
"""
