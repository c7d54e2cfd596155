"""What every preset family shares: the scene format's version, the camera's defaults,
the textures that scikit-image ships, the key of box and envmap, frames and panels in
the room, and a sphere's outline in the image.

Frames: the OpenCV camera frame is the world frame (+x right, +y down, +z forward;
metres); room coordinates have y down along gravity and z forward horizontal.
"""

from __future__ import annotations

import numpy as np

from scenes import camera

FORMAT = 1
FOV_X_DEG = 60.0
PITCH_DEG = 14.0            # camera looks this much below the horizon
CAMERA_HEIGHT = 1.0         # metres above the floor
MAX_DEPTH = 8               # path length: enough for light to pass through the glass

# Textures that scikit-image ships (``skimage.data.<name>``), no download needed.
# Grey ones are tinted with a random colour; photographs are used as they are.
GREY_TEXTURES = ("brick", "grass", "gravel", "camera", "moon", "coins", "text",
                 "checkerboard", "clock", "page")
PHOTO_TEXTURES = ("astronaut", "coffee", "chelsea", "rocket", "hubble_deep_field",
                  "immunohistochemistry", "colorwheel", "retina", "cat")
WALL_TEXTURES = ("brick", "grass", "gravel", "camera", "moon", "coins", "checkerboard",
                 "text", "hubble_deep_field", "immunohistochemistry", "astronaut")
FLOOR_TEXTURES = ("gravel", "brick", "grass", "checkerboard", "coins")
ENV_PHOTOS = ("rocket", "coffee", "chelsea", "astronaut", "cat")

TOTEM_RADIUS = 0.1
TOTEM_IOR = 1.52


# --------------------------------------------------------------------------- frames

def pitch_rotation(deg: float) -> np.ndarray:
    """Rotation taking room coordinates (y down along gravity, z forward horizontal)
    to the camera frame of a camera pitched ``deg`` degrees down."""
    t = np.radians(deg)
    c, s = np.cos(t), np.sin(t)
    # camera down = (0, c, -s) and camera forward = (0, s, c) in room coordinates
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def affine(M: np.ndarray, t) -> np.ndarray:
    """The 4x4 homogeneous transform of rotation/scale ``M`` (3x3) then translation ``t``."""
    A = np.eye(4)
    A[:3, :3] = M
    A[:3, 3] = t
    return A


def panel(center, normal, down, width, height) -> np.ndarray:
    """``to_world`` of Mitsuba's ``rectangle`` ([-1, 1]^2, z = 0, normal +z) as a
    ``width`` x ``height`` panel whose front faces ``normal``.

    ``down`` is the direction in which the texture's rows go as seen from the front;
    the texture then reads upright and not mirrored (columns go along
    ``right = down x forward`` with ``forward = -normal``, as in the OpenCV frame).
    """
    n = np.asarray(normal, float)
    n /= np.linalg.norm(n)
    d = np.asarray(down, float)
    d -= n * (d @ n)
    d /= np.linalg.norm(d)
    r = np.cross(d, -n)
    return affine(np.stack([r * width / 2, d * height / 2, n], axis=1), center)


def yaw_rotation(deg: float) -> np.ndarray:
    """Rotation about the room's vertical axis (y)."""
    t = np.radians(deg)
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])



# --------------------------------------------------------------------------- totems

def sphere_outline(K: np.ndarray, center, radius: float, n: int = 64) -> np.ndarray:
    """Pixels (n, 2) of a sphere's silhouette: the projected circle of tangency."""
    P = np.asarray(center, float)
    dist2 = P @ P
    C = P * (1.0 - radius ** 2 / dist2)                # centre of the tangency circle
    T = radius * np.sqrt(1.0 - radius ** 2 / dist2)    # its radius
    a = np.cross(P, [0.0, 1.0, 0.0] if abs(P[1]) < 0.9 * np.sqrt(dist2) else [1.0, 0, 0])
    a /= np.linalg.norm(a)
    b = np.cross(P / np.sqrt(dist2), a)
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)[:, None]
    return camera.project(K, C + T * (np.cos(t) * a + np.sin(t) * b))
