"""The scene folder and the camera, and what makes, edits and reads scene folders.

The modules here are the core every other room stands on: the scene folder and its files
(`folder`, `files`, `jpeg`), the camera and a sphere's outline in it (`camera`,
`silhouette`), a glass sphere's refraction in numpy (`refraction`), what the totems see
of the camera view and the parallax rule (`reach`), colour (`colour`), selections of the
image (`masks`), the working resolution (`working`), the Dr.Jit backend (`backend`) and
the one bad-input error (`errors`). Around them: `synthetic` (presets rendered with Mitsuba, with their truth),
`channel` (what a camera and a messenger do to a photo), `tamper` (the manipulations),
`photo` (real photos: calibration, ingest, masks) and `plan` (where to put the totems:
the reach a placement predicts before the shot). Frames and units: docs/contract.md.

May import: nothing else of totems (the core); each subpackage says its own.
"""
