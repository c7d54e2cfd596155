"""Where to put the totems, before the shot: the reach a placement predicts.

`predict` is the physics, arrays in and out: the camera's rays and the totems' rays,
refracted through the key's spheres, meeting the subject taken as a plane, and the reach
:func:`scenes.reach.reach_map` gives from them; `suggest` tries moving each totem over a
small grid of image positions and distances and keeps the best single move; `plan` puts
both together as one value (:class:`~scenes.plan.plan.Plan`, ``totems plan``); `files`
draws it (plan.png) and writes it (plan.json).

May import: scenes.
"""
