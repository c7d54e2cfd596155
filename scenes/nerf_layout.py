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

from pathlib import Path

import numpy as np

from scenes import folder
from scenes.errors import BadInput

NERF_RADIUS = 0.1       # metres: configs/*.txt of the NeRF path
NERF_IOR = 1.52         # run.py --ior_totem default


def find_nerf_calib(case_dir: Path, levels: int = 3) -> Path:
    """``calib.npy`` in the case folder or up to ``levels`` folders above it."""
    case_dir = Path(case_dir).resolve()
    for p in [case_dir, *case_dir.parents][:levels + 1]:
        if (p / "calib.npy").is_file():
            return p / "calib.npy"
    raise BadInput(f"no calib.npy in {case_dir} or the {levels} folders above it")


def read_nerf_case(case_dir, *, radius: float | None = None, ior: float | None = None,
                   calib=None) -> folder.Scene:
    """A NeRF-path case folder as a :class:`scenes.folder.Scene`.

    The key: ``totems.json`` when the folder has one, else ``radius`` / ``ior`` given
    here, else the NeRF path's values (0.1 m, 1.52). Masks are kept in file order
    (``totem_000`` ... = left to right, as the NeRF path numbers its totems).
    """
    case_dir = Path(case_dir)
    if not case_dir.is_dir():
        raise BadInput(f"NeRF-path case folder not found: {case_dir}")
    image = folder.read_image(case_dir / "image.png", what="photo")
    H, W = image.shape[:2]
    K = folder.read_calib(Path(calib) if calib else find_nerf_calib(case_dir))["mtx"]
    files = sorted((case_dir / "totem_masks").glob("*.png"))
    if not files:
        raise BadInput(f"no totem masks in {case_dir / 'totem_masks'}")
    masks = np.stack([folder.read_mask(f, what="totem mask") for f in files])
    if masks.shape[1:] != (H, W):
        raise BadInput(f"the totem masks of {case_dir} are not the size of image.png")
    n = len(masks)
    if (case_dir / "totems.json").is_file():
        r, eta = folder.read_key(case_dir / "totems.json", n)
    else:
        r = np.full(n, NERF_RADIUS if radius is None else float(radius))
        eta = np.full(n, NERF_IOR if ior is None else float(ior))
        if not (0 < r[0] < 10 and 1 < eta[0] < 4):
            raise BadInput(f"radius must be in metres (0, 10) and ior in (1, 4)")
    initial = None
    if (case_dir / "initial_totem_pose.npy").is_file():
        initial = np.asarray(folder.safe_load_npy(case_dir / "initial_totem_pose.npy"), float)
        if initial.shape != (n, 3) or not np.all(np.isfinite(initial)):
            raise BadInput(f"initial_totem_pose.npy must be ({n}, 3) finite")
    manip = None
    if (case_dir / "manip_mask.png").is_file():
        manip = folder.read_mask(case_dir / "manip_mask.png", what="manipulation mask")
        if manip.shape != (H, W):
            raise BadInput("manip_mask.png is not the size of the photo")
    return folder.Scene(case_dir, image, K, masks, r, eta, initial, manip)
