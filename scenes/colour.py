"""The sRGB transfer function (IEC 61966-2-1), the one home of the colour conversions.

Files hold 8-bit sRGB; the fit and the renderer work in linear RGB.
"""

from __future__ import annotations

import numpy as np

__all__ = ["linear_to_srgb", "srgb_to_linear", "linear_to_srgb_dr"]


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1): linear [0, 1] -> sRGB [0, 1]."""
    x = np.clip(np.nan_to_num(np.asarray(x, np.float32)), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x,
                    1.055 * np.power(x, 1.0 / 2.4) - 0.055).astype(np.float32)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """Inverse of :func:`linear_to_srgb`."""
    x = np.clip(np.asarray(x, np.float32), 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92,
                    np.power((x + 0.055) / 1.055, 2.4)).astype(np.float32)


def linear_to_srgb_dr(x):
    """:func:`linear_to_srgb` on a Dr.Jit array, differentiable (clamped to [1e-6, 1]
    so that the power's gradient stays finite at black)."""
    from scenes import backend

    dr = backend.modules()[0]
    x = dr.clip(x, 1e-6, 1.0)
    return dr.select(x <= 0.0031308, 12.92 * x, 1.055 * dr.power(x, 1 / 2.4) - 0.055)
