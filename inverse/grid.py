"""The frustum voxel grid: its frame (where it sits in the camera frame) and its values.

The grid lives in the camera's projective space, in three unit coordinates

    s = (u - u0) / (u1 - u0),    t = (v - v0) / (v1 - v0),
    r = (1/near - 1/z) / (1/near - 1/far)                  (inverse depth, "disparity")

where ``(u, v) = (fx x/z + cx, fy y/z + cy)`` is the pixel a camera-frame point
``X = (x, y, z)`` (OpenCV, metres) projects to, ``[u0, u1] x [v0, v1]`` is the image
widened by a margin, and ``near < z < far``. The map ``X -> (s, t, r)`` is projective,
so straight lines stay straight (NeRF's NDC does the same): a camera ray is a grid
column (``s, t`` fixed), and any other ray is a straight segment whose points spaced
evenly in ``r`` are spaced evenly along it. Voxels are thin near the camera and deep
far away, which suits a scene seen from a few nearby viewpoints.

Values are kept as Dr.Jit tensors (``mi.TensorXf``), ``(nr, nt, ns, C)`` as
``mi.Texture3f`` wants them (last spatial axis = ``s``): a density grid (1 channel,
before the softplus) and a colour grid (3 channels, linear RGB radiance), each with its
own resolution (the colour may be coarser in depth than the density).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes.camera import project
from scenes.errors import BadInput

__all__ = ["FrustumFrame", "frame_for_scene", "resample", "stage_res", "stage_samples",
           "cells_to_pixels", "cell_centres"]


@dataclass(frozen=True)
class FrustumFrame:
    """Where the grid sits: the camera frustum between ``near`` and ``far``.

    Attributes
    ----------
    K : (3, 3) intrinsics, OpenCV pixel-centre convention.
    u_range, v_range : (lo, hi) pixel coordinates covered in ``s`` and ``t`` (may
        extend beyond the image so that totem rays leaving the view can be kept).
    near, far : depths (camera-frame ``z``, metres) of the grid's first and last slice.
    """

    K: np.ndarray
    u_range: tuple[float, float]
    v_range: tuple[float, float]
    near: float
    far: float

    # ------------------------------------------------------------------ numpy side

    def to_unit(self, X) -> np.ndarray:
        """Camera-frame points ``X`` (..., 3), metres -> unit grid coordinates (..., 3)."""
        X = np.asarray(X, dtype=np.float64)
        uv = project(self.K, X)
        s, t = self.pixel_to_st(uv[..., 0], uv[..., 1])
        r = (1.0 / self.near - 1.0 / X[..., 2]) / (1.0 / self.near - 1.0 / self.far)
        return np.stack([s, t, r], axis=-1)

    def from_unit(self, g) -> np.ndarray:
        """Unit grid coordinates (..., 3) -> camera-frame points (..., 3), metres."""
        g = np.asarray(g, dtype=np.float64)
        K = np.asarray(self.K, dtype=np.float64)
        u = self.u_range[0] + g[..., 0] * (self.u_range[1] - self.u_range[0])
        v = self.v_range[0] + g[..., 1] * (self.v_range[1] - self.v_range[0])
        z = self.depth_at(g[..., 2])
        x = (u - K[0, 2]) / K[0, 0] * z
        y = (v - K[1, 2]) / K[1, 1] * z
        return np.stack([x, y, z], axis=-1)

    def depth_at(self, r):
        """Depth (camera-frame ``z``, metres) at the grid's inverse-depth coordinate
        ``r`` (0 at ``near``, 1 at ``far``); ``r`` keeps its dtype."""
        return 1.0 / (1.0 / self.near - r * (1.0 / self.near - 1.0 / self.far))

    def pixel_to_st(self, u, v) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates -> the grid's ``(s, t)`` (the column a camera ray follows)."""
        s = (np.asarray(u, float) - self.u_range[0]) / (self.u_range[1] - self.u_range[0])
        t = (np.asarray(v, float) - self.v_range[0]) / (self.v_range[1] - self.v_range[0])
        return s, t

    def to_dict(self) -> dict:
        """Plain arrays and numbers (for ``grid.npz``)."""
        return {"K": np.asarray(self.K, dtype=np.float64),
                "u_range": np.asarray(self.u_range, dtype=np.float64),
                "v_range": np.asarray(self.v_range, dtype=np.float64),
                "near": np.float64(self.near), "far": np.float64(self.far)}

    @classmethod
    def from_dict(cls, d) -> "FrustumFrame":
        """Inverse of :meth:`to_dict` (accepts an ``np.load`` result)."""
        try:
            K = np.asarray(d["K"], dtype=np.float64).reshape(3, 3)
            ur = tuple(float(x) for x in np.ravel(d["u_range"]))
            vr = tuple(float(x) for x in np.ravel(d["v_range"]))
            near, far = float(d["near"]), float(d["far"])
        except (KeyError, ValueError, TypeError) as exc:
            raise BadInput(f"grid frame is incomplete or malformed ({exc})") from None
        if len(ur) != 2 or len(vr) != 2 or not (0 < near < far) or ur[1] <= ur[0] \
                or vr[1] <= vr[0] or not np.all(np.isfinite(K)):
            raise BadInput("grid frame is inconsistent (need 0 < near < far, lo < hi)")
        return cls(K, ur, vr, near, far)


def frame_for_scene(K, size, centers, radius, *, margin: float = 0.15,
                    near_factor: float = 0.5, far_factor: float = 1000.0) -> FrustumFrame:
    """A grid frame around the camera view that holds the totems and what they see.

    ``near`` is ``near_factor`` times the nearest totem front (``z - R``), ``far`` is
    ``far_factor`` times the farthest totem centre depth; ``margin`` widens the image
    by that fraction of its size on each side (totem rays leaving the view slightly).

    Parameters
    ----------
    K : (3, 3) intrinsics.
    size : (W, H) pixels.
    centers : (n, 3) totem centres, camera frame, metres.
    radius : (n,) totem radii, metres.
    """
    W, H = size
    centers = np.asarray(centers, dtype=np.float64)
    z_front = float(np.min(centers[:, 2] - np.asarray(radius)))
    if not z_front > 0:
        raise BadInput("a totem reaches behind the camera: check the key's radius")
    near = near_factor * z_front
    far = far_factor * float(np.max(centers[:, 2]))
    mu, mv = margin * W, margin * H
    return FrustumFrame(np.asarray(K, dtype=np.float64), (-0.5 - mu, W - 0.5 + mu),
                        (-0.5 - mv, H - 0.5 + mv), near, far)


def stage_res(res, frac) -> tuple:
    """A grid resolution scaled by a coarse-to-fine stage's fraction (at least 2 cells
    an axis)."""
    return tuple(max(2, int(round(r * frac))) for r in res)


def stage_samples(n: int, frac: float) -> int:
    """Samples per ray in a stage: as the depth resolution, ``n`` scaled by the stage's
    fraction (at least 16)."""
    return max(16, int(round(n * frac)))


def resample(values: np.ndarray, shape) -> np.ndarray:
    """Trilinear resampling of a grid ``(nr, nt, ns, C)`` to ``shape = (nr', nt', ns')``.

    Cell-centred: voxel ``i`` of ``n`` sits at ``(i + 0.5) / n``, as ``mi.Texture3f``
    places it, so the field a texture lookup sees is (up to interpolation) unchanged.
    """
    from scipy.ndimage import map_coordinates

    values = np.asarray(values, dtype=np.float32)
    src = values.shape[:3]
    axes = [((np.arange(n_new) + 0.5) / n_new) * n_old - 0.5
            for n_new, n_old in zip(shape, src)]
    coords = np.stack(np.meshgrid(*axes, indexing="ij"))
    out = np.stack([map_coordinates(values[..., c], coords, order=1, mode="nearest")
                    for c in range(values.shape[3])], axis=-1)
    return out.astype(np.float32)


def cell_centres(frame: FrustumFrame, res):
    """Pixel coordinates (u, v) of the centres of an ``(nt, ns)`` map's cells over the
    frame's ``(s, t)`` range, each (nt, ns)."""
    nt, ns = res
    du = frame.u_range[1] - frame.u_range[0]
    dv = frame.v_range[1] - frame.v_range[0]
    u = frame.u_range[0] + (np.arange(ns) + 0.5) / ns * du
    v = frame.v_range[0] + (np.arange(nt) + 0.5) / nt * dv
    vv, uu = np.meshgrid(v, u, indexing="ij")
    return uu, vv


def cells_to_pixels(cells, frame: FrustumFrame, size, *, nearest: bool = False) -> np.ndarray:
    """A (nt, ns) map over the frame's ``(s, t)`` range, read at every pixel (H, W).

    ``nearest``: the cell each pixel centre falls in. Otherwise bilinear between cell
    centres where the cells around the pixel are known (finite), NaN where the nearest
    cell is unknown.
    """
    from scipy import ndimage

    W, H = size
    nt, ns = cells.shape
    uu, vv = np.meshgrid(np.arange(W), np.arange(H))
    s, t = frame.pixel_to_st(uu.ravel(), vv.ravel())
    fs, ft = np.asarray(s) * ns, np.asarray(t) * nt          # cell i spans [i, i + 1)
    if nearest:
        i = np.clip(fs.astype(int), 0, ns - 1)
        j = np.clip(ft.astype(int), 0, nt - 1)
        return cells[j, i].reshape(H, W)
    fs, ft = fs - 0.5, ft - 0.5                               # cell-centred
    known = np.isfinite(cells)
    filled = np.where(known, cells, 0.0)
    num = ndimage.map_coordinates(filled, [ft, fs], order=1, mode="nearest")
    den = ndimage.map_coordinates(known.astype(np.float64), [ft, fs], order=1,
                                  mode="nearest")
    near = ndimage.map_coordinates(known.astype(np.float64), [ft, fs], order=0,
                                   mode="nearest") > 0.5
    out = np.where(near & (den > 1e-6), num / np.maximum(den, 1e-6), np.nan)
    return out.reshape(H, W)
