"""What a forger without the key makes of the totems: their discs, where a thing of the
camera view shows in them, and the spheres a guessed key gives.

The forgers who edit the totems as well as the camera view (issue 61) hold the photo,
the totems' masks and the camera's ``K``, but not the key (each totem's radius and index
of refraction). Two models of the glass stand in for it:

- the naive one of a forger with an editor (``consistent-paste``): a glass ball shows
  the scene behind it turned by half a turn and shrunk about its disc's centre, as a
  ball lens does near its axis (:func:`naive_scale`, :func:`naive_image_point`), with
  the index of "glass", :data:`GUESSED_IOR`, and the scene far away;
- the physical one of the adaptive forger (``rekey``): spheres of a guessed key, posed
  from the masks (:func:`guessed_spheres`), rendered by Mitsuba.

Frames and units: the OpenCV camera frame (+x right, +y down, +z forward), metres;
pixels (u, v) with pixel centres at integers.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from scenes import masks as masks_mod
from scenes import silhouette
from scenes.errors import BadInput

__all__ = ["GUESSED_IOR", "POSES", "KeyGuess", "disc", "guessed_spheres",
           "naive_image_point", "naive_scale", "parse_key_error"]

GUESSED_IOR = 1.5
"""The index of refraction a forger without the key takes for glass."""

POSES = ("mask", "exact")
"""How the adaptive forger places the spheres: ``mask``, from each totem mask's outline
and the guessed radius (:func:`scenes.silhouette.cone_from_outline`); ``exact``, on the
true outline's cone (the true centre times the guessed over the true radius): no error
but the key's."""


# --------------------------------------------------------------------------- the disc

def disc(mask) -> tuple[float, float, float]:
    """A totem's disc in the image as an editor sees it: the centroid (u, v) of its
    mask and the radius of the disc of the same area, pixels."""
    ys, xs = np.nonzero(np.asarray(mask, bool))
    if ys.size == 0:
        raise ValueError("the disc of an empty mask")
    return float(xs.mean()), float(ys.mean()), float(np.sqrt(ys.size / np.pi))


def naive_scale(radius_px: float, f_px: float, ior: float = GUESSED_IOR) -> float:
    """How much smaller a far thing shows in a glass ball than in the photo, near the
    ball's axis: ``n / (2 (n - 1)) r / f``.

    A ball lens of index ``n`` and radius ``R`` has its focal length ``n R / (2 (n -
    1))`` from its centre; a camera ray that enters it at ``rho R`` from the axis leaves
    at ``rho 2 (n - 1) / n`` radians to it, so a thing at angle ``theta`` off the axis
    shows ``theta n / (2 (n - 1))`` radii from the disc's centre, on the other side.
    ``radius_px`` the disc's radius and ``f_px`` the focal length, pixels.
    """
    return float(ior) / (2.0 * (float(ior) - 1.0)) * float(radius_px) / float(f_px)


def naive_image_point(p, centre, radius_px: float, f_px: float,
                      ior: float = GUESSED_IOR) -> np.ndarray:
    """Where the naive model puts, in a totem's disc, what the photo shows at pixel
    ``p`` (2,) (or (m, 2)): turned by half a turn about the disc's ``centre`` (2,) and
    scaled by :func:`naive_scale`. The totem's own viewpoint is taken as the camera's
    (a far scene: no parallax), so near things land too close to the centre.
    Returns pixels, the shape of ``p``."""
    p = np.asarray(p, np.float64)
    c = np.asarray(centre, np.float64)
    return c - naive_scale(radius_px, f_px, ior) * (p - c)


# --------------------------------------------------------------------------- the key

@dataclass(frozen=True)
class KeyGuess:
    """The adaptive forger's key, as its error against the true one.

    ior : the guessed index of refraction less the true one (each totem's).
    radius : the guessed radius over the true one, less 1 (0.03: 3 % too large).
    pose : one of :data:`POSES`.
    """

    ior: float = 0.0
    radius: float = 0.0
    pose: str = "mask"

    def to_dict(self) -> dict:
        return asdict(self)

    @property
    def exact(self) -> bool:
        """No error at all: the perfect forger who holds the key."""
        return self.ior == 0.0 and self.radius == 0.0 and self.pose == "exact"


def parse_key_error(spec) -> KeyGuess:
    """A :class:`KeyGuess` from ``"ior=0.02,radius=0.03,pose=mask"`` (each part
    optional: 0, 0, ``mask``), a dict of the same, a KeyGuess, or None (no error, the
    pose from the masks). Raises BadInput, in one line, for anything else."""
    if spec is None:
        return KeyGuess()
    if isinstance(spec, KeyGuess):
        return spec
    want = "ior=D,radius=F,pose=mask|exact (e.g. ior=0.02,radius=0.03)"
    if isinstance(spec, str):
        parts = {}
        for item in (x.strip() for x in spec.split(",")):
            name, eq, value = item.partition("=")
            if not eq or not name.strip() or name.strip() in parts:
                raise BadInput(f"--key-error must be {want}, got {spec!r}")
            parts[name.strip()] = value.strip()
        spec = parts
    if not isinstance(spec, dict):
        raise BadInput(f"--key-error must be {want}, got {spec!r}")
    unknown = set(spec) - {"ior", "radius", "pose"}
    if unknown:
        raise BadInput(f"--key-error has no part {sorted(unknown)[0]!r}: use {want}")
    try:
        ior, radius = float(spec.get("ior", 0.0)), float(spec.get("radius", 0.0))
    except (TypeError, ValueError):
        raise BadInput(f"--key-error must be {want}, got {spec!r}") from None
    pose = str(spec.get("pose", "mask"))
    if not (math.isfinite(ior) and math.isfinite(radius)):
        raise BadInput(f"--key-error's ior and radius must be finite numbers, got {spec!r}")
    if abs(ior) >= 1.0 or not -1.0 < radius < 10.0:
        raise BadInput(f"--key-error: ior must be within +-1 and radius (relative) in "
                       f"(-1, 10), got ior={ior:g}, radius={radius:g}")
    if pose not in POSES:
        raise BadInput(f"--key-error's pose must be one of {', '.join(POSES)}, got {pose!r}")
    return KeyGuess(ior + 0.0, radius + 0.0, pose)


def guessed_spheres(masks, K, spheres, guess: KeyGuess) -> list[dict]:
    """The spheres the adaptive forger renders in place of the totems.

    Parameters
    ----------
    masks : (n, H, W) bool, the totems' masks, in the order of ``spheres``.
    K : (3, 3) OpenCV intrinsics, pixels.
    spheres : n dicts ``{"center": (3,) m, "radius": m, "ior": n}``, the true totems.
    guess : the forger's key error.

    Returns
    -------
    n dicts ``{"center", "radius", "ior"}`` (camera frame, metres): radius ``R (1 +
    guess.radius)``, index ``n + guess.ior``, centre from the mask's outline and that
    radius (``pose`` ``mask``) or the true centre times ``1 + guess.radius`` (``exact``:
    on the true outline's cone). Raises BadInput for a guessed index <= 1.
    """
    out = []
    for m, t in zip(masks, spheres):
        R, n = float(t["radius"]), float(t["ior"])
        Rg, ng = R * (1.0 + guess.radius), n + guess.ior
        if ng <= 1.0:
            raise BadInput(f"--key-error ior={guess.ior:g} gives a totem of index "
                           f"{ng:.3f}, not glass (> 1)")
        if guess.pose == "exact":
            P = np.asarray(t["center"], np.float64) * (Rg / R)
        else:
            q = silhouette.cone_from_outline(masks_mod.outline(m), K)
            P = silhouette.sphere_from_circle(*q, K, Rg)
        out.append({"center": [float(c) for c in P], "radius": Rg, "ior": ng})
    return out
