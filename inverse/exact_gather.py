"""Gathers whose adjoint adds in fixed point: a gradient the same on any number of threads.

The reverse of a gather is a scatter-add. In floating point its sum depends on the order
in which the threads add, so two backward passes on two threads differ in their last
bits and two fits of one photo drift apart; in integers addition is associative and the
order cannot change the sum. So each contribution ``g`` to a cell is rounded to the
64-bit integer ``round(g * 2**FRAC_BITS)``, the integers are added (atomically, in any
order), and the cell's sum is converted back to a float.

Bounds: each contribution is off by at most ``2**-(FRAC_BITS + 1)`` (4.5e-13), so a cell
that gathers ``m`` contributions is off by at most ``m * 2**-(FRAC_BITS + 1)`` before the
final rounding to float32; a contribution or a cell's sum must stay below
``2**(62 - FRAC_BITS)`` (4.2e6) in magnitude (contributions beyond it are clipped). A
fit's gradients are far inside both: its largest cell gradient is below 1e-3, and Adam's
epsilon 1e-8 is 1e4 quanta (docs/decisions.md, "fit: the backward pass on two threads,
in fixed point").
"""

from __future__ import annotations

import sys

from scenes import backend

__all__ = ["FRAC_BITS", "gather", "grid_at", "backward"]

FRAC_BITS = 40
_CLIP = float(2 ** 62)
_OP = []
_PENDING = []        # while :func:`backward` runs: {AD index: (source, accumulator)}


class _Source:
    """The attached array a gather reads (an opaque argument to ``dr.custom``)."""

    def __init__(self, x, defer: bool):
        self.x, self.defer = x, defer


def _gather_op():
    dr, mi = backend.modules()

    class _FixedPointGather(dr.CustomOp):
        """``len(index) * channels`` gathers from the flat array ``x`` (cell ``i``,
        channel ``c`` at ``i * channels + c``); their adjoints summed in fixed point."""

        def eval(self, x, index, channels, mode, source):
            self.index, self.channels, self.mode, self.source = index, channels, mode, source
            self.size = dr.width(x)
            if channels == 1:
                return [dr.gather(mi.Float, x, i) for i in index]
            # Channels padded to a packet: one gather a cell, not one a channel.
            P = 1 << (channels - 1).bit_length()
            j = dr.arange(mi.UInt32, self.size // channels * P)
            c = j % P
            x_p = dr.gather(mi.Float, x, j // P * channels + dr.minimum(c, channels - 1),
                            c < channels)
            Packet = getattr(sys.modules[type(x).__module__], f"Array{P}f")
            return [v[c] for i in index for v in (dr.gather(Packet, x_p, i),)
                    for c in range(channels)]

        def backward(self):
            key = self.source.x.index_ad
            deferred = bool(_PENDING) and self.source.defer
            if deferred and key in _PENDING[0]:
                acc = _PENDING[0][key][1]
            else:
                acc = _Accumulator(self.size, self.channels)
            g = self.grad_out()
            C = self.channels
            for k, i in enumerate(self.index):
                acc.add(g[k * C:(k + 1) * C], i, self.mode)
            if deferred:
                _PENDING[0][key] = (self.source.x, acc)
            else:
                self.set_grad_in("x", acc.value())

        def name(self):
            return "FixedPointGather"

    return _FixedPointGather


class _Accumulator:
    """A flat array's gradient in 64-bit fixed point: cell ``i``'s ``C`` channels at
    ``i * P``, ``P`` the power of two at or above ``C`` (a packet: one scatter a cell)."""

    def __init__(self, size: int, channels: int):
        dr, mi = backend.modules()
        self.C = channels
        self.P = 1 << (channels - 1).bit_length()
        self.Int64 = dr.int64_array_t(mi.Float)
        self.Packet = getattr(sys.modules[type(mi.Float()).__module__], f"Array{self.P}i64",
                              None) if self.P > 1 else None
        self.acc = dr.zeros(self.Int64, size // channels * self.P)

    def add(self, g, i, mode) -> None:
        """Add the channels ``g`` (list of ``mi.Float`` per lane) to cells ``i``."""
        dr = backend.modules()[0]
        scale = float(2 ** FRAC_BITS)
        q = [self.Int64(dr.round(dr.clip(gc * scale, -_CLIP, _CLIP))) for gc in g]
        if self.P == 1:
            dr.scatter_reduce(dr.ReduceOp.Add, self.acc, q[0], i, mode=mode)
            return
        q += [self.Int64(0)] * (self.P - self.C)
        dr.scatter_reduce(dr.ReduceOp.Add, self.acc, self.Packet(*q), i,
                          mode=dr.ReduceMode.Expand)

    def value(self):
        """The sum as ``mi.Float``, laid out as the source (``i * C + c``)."""
        dr, mi = backend.modules()
        inv = 1.0 / float(2 ** FRAC_BITS)
        if self.P == self.C:
            return mi.Float(self.acc) * inv
        j = dr.arange(mi.UInt32, dr.width(self.acc) // self.P * self.C)
        return mi.Float(dr.gather(self.Int64, self.acc, j // self.C * self.P + j % self.C)) * inv


def gather(x, index, *, channels: int = 1, mode=None, defer: bool = False):
    """``x[i * channels + c]`` for each index array ``i`` of ``index`` (``mi.UInt32``
    per lane) and channel ``c``, as a list (index-major) of ``mi.Float``; the gradient
    reaching ``x`` is summed in 64-bit fixed point (``FRAC_BITS`` fractional bits), so it
    is the same to the bit however the backward pass's threads are scheduled.

    ``mode`` is the integer scatter's ``dr.ReduceMode`` (default ``Direct``). With
    ``defer`` (``x`` must then be a leaf of the AD graph, as an optimised parameter is)
    and inside :func:`backward`, the sum reaches ``x`` after the traversal, so the
    integer scatters run in the traversal's one kernel instead of one of their own.
    """
    dr = backend.modules()[0]
    if not _OP:
        _OP.append(_gather_op())
    mode = dr.ReduceMode.Direct if mode is None else mode
    return dr.custom(_OP[0], x, list(index), channels, mode, _Source(x, defer))


def backward(loss) -> None:
    """``dr.backward(loss)``; the deferred fixed-point sums (:func:`gather`) then added
    to the gradients of their sources."""
    dr = backend.modules()[0]
    _PENDING.append({})
    try:
        dr.backward(loss)
    finally:
        pending = _PENDING.pop()
    for x, acc in pending.values():
        dr.accum_grad(x, acc.value())


def grid_at(texture, p, *, mode=None):
    """The values of a ``mi.Texture2f`` / ``mi.Texture3f`` at unit points ``p``
    (``mi.Point3f``; ``p.z`` unused in 2-D), linear between cell centres and clamped at
    the edges, as the texture's own ``eval`` (to float32's rounding of the position), as a list of
    ``mi.Float``, one a channel; read by :func:`gather`, so their gradients reaching the
    texture's tensor are the same on any number of threads, and those reaching ``p``
    follow the weights as usual.
    """
    dr, mi = backend.modules()
    t = texture.tensor()
    *cells, C = t.shape
    sizes = cells[::-1]                                      # W, H[, D]
    w, ends = [], []
    for a, n in zip((p.x, p.y, p.z), sizes):
        f = a * n - 0.5
        b = dr.floor(f)
        w.append(f - b)                                      # weight of the upper cell
        b = mi.Int32(b)
        ends.append((mi.UInt32(dr.clip(b, 0, n - 1)), mi.UInt32(dr.clip(b + 1, 0, n - 1))))
    index = []                                               # corners, x fastest
    for corner in range(2 ** len(sizes)):
        flat = mi.UInt32(0)
        for axis in reversed(range(len(sizes))):
            flat = flat * sizes[axis] + ends[axis][(corner >> axis) & 1]
        index.append(flat)
    vals = gather(t.array, index, channels=C, mode=mode, defer=True)
    out = []
    for c in range(C):
        v = vals[c::C]
        for wa in w:                                          # x, then y, then z
            v = [dr.lerp(v[k], v[k + 1], wa) for k in range(0, len(v), 2)]
        out.append(v[0])
    return out
