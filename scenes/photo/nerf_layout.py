"""Read a case of the NeRF path's data set as it is (``jingweim/totems``, README
"Pre-compiled data")::

    data-compiled/calib.npy            shared: 'mtx' (K of image.png), 'roi', ('dist')
    data-compiled/<kind>/<case>/image.png, totem_masks/totem_000.png ...,
                                initial_totem_pose.npy, manip_mask.png (manipulated)

The NeRF path has no key file: radius comes from its config (``totem_radius``, 0.1 m in
its released configs, no default) and IoR from ``--ior_totem`` (default 1.52). Its
totem j is ``totem_masks/totem_{j:03d}.png`` (README: "0-n = left-right").
"""

from __future__ import annotations

from scenes import folder

__all__ = ["NERF_RADIUS", "NERF_IOR", "read_nerf_case"]

NERF_RADIUS = 0.1       # metres: configs/*.txt of the NeRF path
NERF_IOR = 1.52         # run.py --ior_totem default


def read_nerf_case(case_dir, *, radius: float | None = None,
                   ior: float | None = None) -> folder.Scene:
    """A NeRF-path case folder as a :class:`scenes.folder.Scene`.

    The key: ``totems.json`` when the folder has one, else ``radius`` / ``ior`` given
    here, else the NeRF path's values (0.1 m, 1.52). ``calib.npy`` is found in the case
    folder or up to two folders above it (``data-compiled/calib.npy``).
    """
    key = (NERF_RADIUS if radius is None else radius, NERF_IOR if ior is None else ior)
    return folder.read_scene(case_dir, default_key=key)
