"""The manipulations: manipulated copies of a scene folder, with what was changed.

`edits` holds what every forger shares (an edit, its source scene, where it goes);
`edits2d` the forger's pixel tools; `tamper3d` the forgeries that re-render the scene
from its truth; `tamper` writes the manipulated copy (`totems tamper`).

May import: scenes, scenes.synthetic.
"""
