"""Real photos: camera calibration, a photo into a scene folder, and totem masks.

`calibrate` (`totems calib`) and `ingest` (`totems ingest`) bring a camera's photo in;
`detect_masks` proposes totem masks (`totems masks`) with `cone_fit` and `glass`;
`drawn_masks` changes exact masks the way people draw them; `nerf_layout` reads a case of
the NeRF path's data set as it is.

May import: scenes.
"""
