"""Totem pose: each sphere's centre in the camera frame, from its mask and the photo.

`pose` from the mask's outline and the key; `rim` from the photo's own edges; `combined`
weighs both by what each is worth; `shared` what the totems of one photo share (how their
masks were drawn).

May import: inverse, scenes.
"""
