"""The capture channel: what a camera, then a messenger, does to a photo.

Plain functions on (H, W, 3) float32 sRGB arrays in [0, 1] (sRGB unless said linear),
and :func:`plan` / :func:`apply`, which run them in this order:

    camera     1 blur      defocus: Gaussian, sigma in pixels, on linear light (optics
                           act before the sensor)
               2 tone      exposure gain on linear light (clipped at 1, as a sensor
                           saturates), then the gamma curve out = in ** (1 / gamma) on
                           sRGB values (gamma > 1 lifts the mid-tones)
               3 noise     Gaussian, sigma in 8-bit levels (1/255 of sRGB), independent
                           per pixel and channel, after the tone curve: the noise as it
                           is measured in the file (photon noise on the linear raw is
                           :func:`photon_noise`, for ``scene make --camera``)
               4 sharpen   unsharp mask (radius 1 px, ``amount``), after the noise, which
                           in-camera sharpening amplifies as real cameras do
               5 jpeg      the camera's JPEG(s)
    messenger  6 resize    by one scale on both axes (area interpolation), downscaling only
               7 jpeg      the messenger's re-encoding: with a resize, the last of the
                           qualities asked for comes after it, the others before it;
                           without one, all are applied in turn (double JPEG)

A step left at its neutral value (blur 0, gain 1 and gamma 1, noise 0, sharpen 0, no
resize, no JPEG) is left out of the plan. Photos stay 8-bit between steps: every
JPEG decodes to 8-bit values, and :func:`apply` rounds its result to them.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass

import numpy as np

from scenes import jpeg
from scenes.colour import linear_to_srgb, srgb_to_linear
from scenes.errors import BadInput

__all__ = ["MIN_SIDE", "SHARPEN_RADIUS", "FULL_WELL_E", "READ_NOISE_E", "Channel", "blur",
           "tone", "add_noise", "sharpen", "resize", "resize_mask", "photon_noise",
           "plan", "apply", "noise_rng"]

MIN_SIDE = 16                 # px: the smallest photo a resize may give
SHARPEN_RADIUS = 1.0          # px: the Gaussian of the in-camera unsharp mask
FULL_WELL_E = 4000.0          # electrons at linear 1.0: a small (phone) sensor at base ISO
READ_NOISE_E = 3.0            # electrons rms: its read noise


@dataclass(frozen=True)
class Channel:
    """A channel's settings, as ``totems recapture`` takes them.

    jpeg : JPEG qualities (1-100), in the order applied (two or more: double JPEG).
    chroma : "420" or "444", for every JPEG.
    resize : scale factor in (0, 1], or None.
    long_side : the photo's long side after the resize (px), or None; a photo already
        that small is left as it is (messengers do not enlarge).
    noise : sigma in 8-bit levels (>= 0).
    blur : defocus sigma in pixels (>= 0).
    sharpen : unsharp-mask amount (>= 0; 1 adds the detail once more).
    exposure : gain on linear light (> 0). gamma : the tone curve's gamma (> 0).
    seed : the noise's seed, beside the photo's set-up (:func:`noise_rng`).
    """

    jpeg: tuple[int, ...] = ()
    chroma: str = "420"
    resize: float | None = None
    long_side: int | None = None
    noise: float = 0.0
    blur: float = 0.0
    sharpen: float = 0.0
    exposure: float = 1.0
    gamma: float = 1.0
    seed: int = 0


# --------------------------------------------------------------------------- the steps

def blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur, ``sigma`` in pixels (kernel out to 4 sigma, edges reflected)."""
    import cv2

    if sigma <= 0:
        return np.asarray(image, np.float32)
    k = 2 * math.ceil(4.0 * sigma) + 1
    return cv2.GaussianBlur(np.asarray(image, np.float32), (k, k), sigmaX=float(sigma),
                            sigmaY=float(sigma), borderType=cv2.BORDER_REFLECT_101)


def tone(image: np.ndarray, *, exposure: float = 1.0, gamma: float = 1.0) -> np.ndarray:
    """The tone curve: sRGB -> linear, times ``exposure`` (clipped at 1), -> sRGB, then
    ``** (1 / gamma)``. Returns sRGB in [0, 1]."""
    out = linear_to_srgb(np.clip(srgb_to_linear(image) * float(exposure), 0.0, 1.0))
    if gamma != 1.0:
        out = np.power(out, 1.0 / float(gamma)).astype(np.float32)
    return out


def add_noise(image: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Add Gaussian noise of ``sigma`` 8-bit levels (sigma / 255 in sRGB), clipped to
    [0, 1]. The field is ``sigma`` times one standard normal draw of the image's shape,
    so one generator gives one pattern at every sigma."""
    field = rng.standard_normal(np.shape(image), dtype=np.float32)
    return np.clip(np.asarray(image, np.float32) + (float(sigma) / 255.0) * field,
                   0.0, 1.0)


def sharpen(image: np.ndarray, amount: float, *,
            radius: float = SHARPEN_RADIUS) -> np.ndarray:
    """Unsharp mask: ``image + amount (image - blur(image, radius))``, clipped."""
    from skimage.filters import unsharp_mask

    return unsharp_mask(np.asarray(image, np.float32), radius=radius, amount=float(amount),
                        channel_axis=-1, preserve_range=True).clip(0.0, 1.0) \
        .astype(np.float32)


def resize(image: np.ndarray, scale: float) -> np.ndarray:
    """The image scaled by ``scale`` on both axes with area interpolation.

    The size is (round(W scale), round(H scale)); the content scales by ``scale``
    exactly (not by the rounded size's ratio), so the resized image's K is
    :func:`scenes.camera.scale_intrinsics` (K, scale) and fx = fy is kept.
    """
    import cv2

    arr = np.asarray(image, np.float32)
    return cv2.resize(arr, None, fx=float(scale), fy=float(scale),
                      interpolation=cv2.INTER_AREA)


def resize_mask(mask: np.ndarray, scale: float, *, threshold: float = 0.5) -> np.ndarray:
    """A bool mask resized as :func:`resize`: a pixel is set when more than
    ``threshold`` of its area was (0.5 for a totem's silhouette; 0 for a manipulation,
    where any changed pixel mixed in makes the pixel changed)."""
    return resize(np.asarray(mask, np.float32), scale) > threshold + 1e-6


def photon_noise(linear: np.ndarray, rng: np.random.Generator, *,
                 full_well: float = FULL_WELL_E,
                 read_noise: float = READ_NOISE_E) -> np.ndarray:
    """A sensor's noise on linear light (Poisson-Gaussian): ``full_well`` electrons at
    1.0, a Poisson count of them per pixel and channel, plus Gaussian read noise of
    ``read_noise`` electrons. Returns linear values (not clipped)."""
    lin = np.clip(np.asarray(linear, np.float64), 0.0, None)
    electrons = rng.poisson(lin * full_well) + rng.normal(0.0, read_noise, lin.shape)
    return (electrons / full_well).astype(np.float32)


# --------------------------------------------------------------------------- the order

def plan(channel: Channel, size) -> list[list]:
    """The channel's steps for a photo of ``size`` (W, H), in the module's order.

    Each step is ``[name, value]`` (JSON-ready): ``["blur", sigma]``, ``["tone",
    [exposure, gamma]]``, ``["noise", sigma]``, ``["sharpen", amount]``, ``["jpeg",
    [quality, chroma]]``, ``["resize", scale]``. Raises BadInput for values outside
    their ranges, or a resize that leaves a side under :data:`MIN_SIDE` pixels.
    """
    c = channel
    W, H = (int(v) for v in size)
    for name, v, lo in (("--noise", c.noise, 0.0), ("--blur", c.blur, 0.0),
                        ("--sharpen", c.sharpen, 0.0)):
        if not (math.isfinite(v) and v >= lo):
            raise BadInput(f"{name} must be a number >= 0, got {v}")
    for name, v in (("--exposure", c.exposure), ("--gamma", c.gamma)):
        if not (math.isfinite(v) and v > 0):
            raise BadInput(f"{name} must be a positive number, got {v}")
    if c.blur > 100:
        raise BadInput(f"--blur sigma must be at most 100 px, got {c.blur}")
    for q in c.jpeg:
        if not (isinstance(q, (int, np.integer)) and 1 <= q <= 100):
            raise BadInput(f"--jpeg quality must be a whole number 1-100, got {q}")
    if str(c.chroma) not in ("420", "444"):
        raise BadInput(f"--chroma must be 420 or 444, got {c.chroma}")
    scale = _scale(c, W, H)
    steps = []
    if c.blur > 0:
        steps.append(["blur", float(c.blur)])
    if c.exposure != 1.0 or c.gamma != 1.0:
        steps.append(["tone", [float(c.exposure), float(c.gamma)]])
    if c.noise > 0:
        steps.append(["noise", float(c.noise)])
    if c.sharpen > 0:
        steps.append(["sharpen", float(c.sharpen)])
    qualities = [["jpeg", [int(q), str(c.chroma)]] for q in c.jpeg]
    if scale is None:
        return steps + qualities
    return steps + qualities[:-1] + [["resize", scale]] + qualities[-1:]


def _scale(c: Channel, W: int, H: int) -> float | None:
    if c.resize is not None and c.long_side is not None:
        raise BadInput("give --resize or --long-side, not both")
    if c.resize is not None:
        if not (math.isfinite(c.resize) and 0 < c.resize <= 1):
            raise BadInput(f"--resize must be a factor in (0, 1] (messengers shrink "
                           f"photos), got {c.resize}")
        scale = float(c.resize)
    elif c.long_side is not None:
        if not (isinstance(c.long_side, (int, np.integer)) and c.long_side > 0):
            raise BadInput(f"--long-side must be a positive whole number of pixels, "
                           f"got {c.long_side}")
        if c.long_side >= max(W, H):
            return None
        scale = c.long_side / max(W, H)
    else:
        return None
    if scale == 1.0:
        return None
    w, h = round(W * scale), round(H * scale)
    if min(w, h) < MIN_SIDE:
        raise BadInput(f"a resize by {scale:.4g} would leave the {W}x{H} photo {w}x{h}; "
                       f"keep at least {MIN_SIDE} px a side")
    return scale


def apply(image: np.ndarray, steps, *, rng: np.random.Generator | None = None
          ) -> tuple[np.ndarray, bytes | None]:
    """Run ``steps`` (:func:`plan`) on an sRGB photo.

    Returns (the photo, (H', W', 3) float32 sRGB at 8-bit values k / 255; the last
    JPEG's bytes when the last step is a JPEG, else None). ``rng`` draws the noise
    (needed when a step is noise). The input is not modified.
    """
    out = np.asarray(image, np.float32).copy()
    data = None
    for name, value in steps:
        data = None
        if name == "blur":
            out = linear_to_srgb(blur(srgb_to_linear(out), value))
        elif name == "tone":
            out = tone(out, exposure=value[0], gamma=value[1])
        elif name == "noise":
            if rng is None:
                raise ValueError("a noise step needs rng")
            out = add_noise(out, value, rng)
        elif name == "sharpen":
            out = sharpen(out, value)
        elif name == "resize":
            out = resize(out, value)
        elif name == "jpeg":
            data = jpeg.encode(out, quality=value[0], chroma=value[1])
            out = jpeg.decode(data)
        else:
            raise ValueError(f"unknown channel step {name!r}")
    out = (np.clip(out, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8).astype(np.float32) / 255.0
    return out, data


def noise_rng(setup: bytes, seed: int) -> np.random.Generator:
    """The noise generator of a photo: seeded by the sha256 of its set-up (``setup``:
    what an edit outside the totems leaves as it is, e.g. size, K and masks) and
    ``seed``, so an untouched photo and its edited copies, recaptured with one seed,
    get one noise pattern and differ only where they were edited."""
    digest = hashlib.sha256(setup + json.dumps(["noise", int(seed)]).encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:16], "little"))
