"""Synthetic totem-protected scenes: presets, placements, textures, rendering with truth.

`presets` draws a random scene description (a dict) per preset and seed from the parts in
`preset_parts`, `preset_kit` and the families `preset_outdoor`, `preset_rooms`,
`preset_tabletop`; `placement` says where the totems stand; `textures` paints the
surfaces; `render` renders a description with Mitsuba 3 (photo, ids, masks, depth);
`trace` traces where the camera's and the totems' rays truly land (the truth's reach);
`make` writes it as a scene folder with its `truth/`.

May import: scenes, scenes.channel.
"""
