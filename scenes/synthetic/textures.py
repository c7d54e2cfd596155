"""Procedural textures and the horizon panorama, as sRGB images for the renderer.

A procedural texture is named ``"<kind>:<seed>"`` wherever a scene description names a
texture (``material.texture``, a light's ``texture``); the same name always gives the
same pixels, so the description stays the whole scene. Kinds:

``wood``    planks' grain: bands warped by smooth noise (colour)
``marble``  veins: a sine of a turbulent field (colour)
``blobs``   blobs like ``skimage.data.binary_blobs``' (grey: tint it)
``noise``   smooth multi-scale noise, like plaster, carpet or soil (grey: tint it)

Images are (256, 256, 3) uint8 sRGB and tile seamlessly (the noise is filtered with
wrap-around, the sines have whole periods across the image).
"""

from __future__ import annotations

import functools

import numpy as np

from scenes.errors import BadInput

__all__ = ["KINDS", "GREY_KINDS", "SIZE", "is_procedural", "procedural",
           "horizon_panorama"]

KINDS = ("wood", "marble", "blobs", "noise")
GREY_KINDS = ("blobs", "noise")
SIZE = 256


def is_procedural(name: str) -> bool:
    """True for a ``"<kind>:<seed>"`` texture name."""
    return ":" in str(name)


def _parse(name: str) -> tuple[str, int]:
    kind, _, seed = str(name).partition(":")
    if kind not in KINDS or not seed.isdigit():
        raise BadInput(f"unknown procedural texture {name!r}: use '<kind>:<seed>' with "
                       f"kind one of {', '.join(KINDS)} and a non-negative integer seed")
    return kind, int(seed)


def _smooth_noise(rng, sigmas=(32, 12, 4), weights=(1.0, 0.5, 0.25)) -> np.ndarray:
    """Sum of Gaussian-filtered white noise at several scales (pixels), in [0, 1]."""
    from skimage.filters import gaussian

    field = np.zeros((SIZE, SIZE))
    for s, w in zip(sigmas, weights):
        n = gaussian(rng.standard_normal((SIZE, SIZE)), sigma=s, mode="wrap")
        field += w * n / (n.std() + 1e-12)
    field -= field.min()
    return field / (field.max() + 1e-12)


def _colour_ramp(t: np.ndarray, dark, light) -> np.ndarray:
    """sRGB uint8 image blending two sRGB colours (0-255) by ``t`` in [0, 1]."""
    dark, light = np.asarray(dark, float), np.asarray(light, float)
    img = dark + t[..., None] * (light - dark)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _wood(rng) -> np.ndarray:
    """Planks' grain: bands across the rows, warped by smooth noise."""
    y = np.arange(SIZE)[:, None] / SIZE
    warp = _smooth_noise(rng, (24, 6), (1.0, 0.3))
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * (int(rng.integers(8, 16)) * y + 0.5 * warp))
    t = 0.65 * grain ** 2 + 0.35 * _smooth_noise(rng, (2, 1), (1.0, 0.5))
    base = rng.uniform(0.6, 1.0)
    return _colour_ramp(t, np.array([95, 55, 25]) * base, np.array([200, 145, 90]) * base)


def _marble(rng) -> np.ndarray:
    """Veins: a sine along an integer direction (so it tiles) of a turbulent field."""
    y, x = np.mgrid[0:SIZE, 0:SIZE] / SIZE
    kx, ky = rng.integers(1, 4, 2)
    turb = _smooth_noise(rng, (24, 8, 3), (1.0, 0.6, 0.3))
    t = np.abs(np.sin(np.pi * (kx * x + ky * y + 2.5 * turb)))
    light = np.array([235, 232, 225]) * rng.uniform(0.85, 1.0)
    dark = np.array([90, 95, 100]) * rng.uniform(0.6, 1.2)
    return _colour_ramp(t ** 0.35, dark, light)


def _blobs(rng) -> np.ndarray:
    """Blobs as in ``skimage.data.binary_blobs`` (smoothed noise over a threshold),
    but periodic."""
    from skimage.filters import gaussian

    field = gaussian(rng.standard_normal((SIZE, SIZE)), sigma=rng.uniform(6, 14),
                     mode="wrap")
    b = field > np.quantile(field, rng.uniform(0.4, 0.7))
    t = gaussian(b.astype(float), sigma=1.0, mode="wrap")
    return _colour_ramp(t, [70] * 3, [235] * 3)


def _noise(rng) -> np.ndarray:
    t = _smooth_noise(rng, (16, 5, 1.5), (1.0, 0.6, rng.uniform(0.2, 0.8)))
    return _colour_ramp(t, [60] * 3, [235] * 3)


@functools.lru_cache(maxsize=64)
def procedural(name: str) -> np.ndarray:
    """The texture ``"<kind>:<seed>"`` as (256, 256, 3) uint8 sRGB (module docstring)."""
    kind, seed = _parse(name)
    rng = np.random.default_rng([seed, KINDS.index(kind), 99])
    img = {"wood": _wood, "marble": _marble, "blobs": _blobs, "noise": _noise}[kind](rng)
    img.setflags(write=False)
    return img


def horizon_panorama(photo: np.ndarray, zenith, horizon, ground, *,
                     h: int = 256, band_deg: float = 6.0) -> np.ndarray:
    """A 2:1 lat-long panorama (sRGB uint8, row 0 the zenith) of an outdoor place.

    A band of ``band_deg`` degrees above the horizon holds ``photo`` an even number of
    times around at about its aspect ratio (mirrored every other time so the ends
    meet), like distant scenery; above it the sky goes from ``horizon`` to ``zenith``
    (sRGB 0-1); below the horizon lies a uniform ``ground`` (sRGB 0-1), which the
    scene's ground plane mostly hides.
    """
    from skimage.transform import resize

    hb = max(2, round(h * band_deg / 90.0))
    pairs = max(1, round(h / (hb * photo.shape[1] / photo.shape[0])))
    tile = resize(photo, (hb, h // pairs), order=1, preserve_range=True,
                  anti_aliasing=True)
    band = np.concatenate([tile, tile[:, ::-1]] * pairs, axis=1)
    band = resize(band, (hb, 2 * h), order=1, preserve_range=True)
    rows = h - hb
    # elevation from 90 deg (row 0) down to band_deg; the sky's blend is steeper near
    # the horizon, as a clear sky's is
    t = (np.arange(rows)[:, None, None] + 0.5) / rows
    sky = 255.0 * (np.asarray(zenith, float) + (np.asarray(horizon, float)
                                                 - np.asarray(zenith, float)) * t ** 2)
    sky = np.broadcast_to(sky, (rows, 2 * h, 3))
    below = np.broadcast_to(255.0 * np.asarray(ground, float), (h, 2 * h, 3))
    pano = np.concatenate([sky, band, below], axis=0)
    return np.clip(np.rint(pano), 0, 255).astype(np.uint8)
