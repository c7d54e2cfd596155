"""Pick the Dr.Jit / Mitsuba variant, once, for the whole process.

CUDA when a GPU is present, else LLVM with a libLLVM that works. libLLVM 15 and 16
abort Dr.Jit 1.5 at the first kernel (``LLVM ERROR: Cannot select ... fminimum``): a
process abort, not an exception. So the library is chosen *before* Dr.Jit loads one:

1. a user's own ``DRJIT_LIBLLVM_PATH`` wins;
2. else the libLLVM shipped by the ``karellen-llvm-core`` wheel (a dependency);
3. else whatever the system has, checked by version before any kernel runs.

The choice is made at the first Dr.Jit use, never when a module is imported: code that
needs Dr.Jit or Mitsuba gets them from :func:`modules` (which calls :func:`use`), in the
function that uses them, so that no ``import drjit`` can run before the library is
chosen.
``TOTEMS_VARIANT`` forces a variant; ``TOTEMS_THREADS`` caps Dr.Jit's worker threads.
"""

from __future__ import annotations

__all__ = ["use", "modules", "describe", "upload", "aligned", "single_thread_blas",
           "one_thread", "BackendError"]

import contextlib
import glob
import os
import sys

import numpy as np

KNOWN_BAD_LLVM = (15, 16)


class BackendError(RuntimeError):
    """No working Dr.Jit backend on this machine."""


_variant: str | None = None


def _wheel_libllvm() -> str | None:
    """Path of the libLLVM shipped by ``karellen-llvm-core``, if installed."""
    try:
        from importlib import metadata
        dist = metadata.distribution("karellen-llvm-core")
        files = [f for f in (dist.files or []) if "libLLVM" in f.name]
        paths = sorted((str(dist.locate_file(f)) for f in files), key=len, reverse=True)
        for p in paths:
            if os.path.isfile(p):
                return os.path.realpath(p)
    except Exception:  # not installed, or metadata unreadable
        pass
    for p in sorted(glob.glob(os.path.join(sys.prefix, "lib", "libLLVM*.so*"))):
        return os.path.realpath(p)
    return None


def _has_cuda() -> bool:
    """True when an NVIDIA driver is visible (checked without initialising Dr.Jit)."""
    if os.environ.get("TOTEMS_NO_CUDA"):
        return False
    import ctypes
    try:
        ctypes.CDLL("libcuda.so.1")
    except OSError:
        return False
    return True


def use(variant: str | None = None) -> str:
    """Set and return the Mitsuba variant (``cuda_ad_rgb`` or ``llvm_ad_rgb``).

    Idempotent: the first call chooses, later calls return the same variant. An
    explicit ``variant`` (or the ``TOTEMS_VARIANT`` environment variable) forces one.

    Raises
    ------
    BackendError
        When only a libLLVM known to crash Dr.Jit is available, with what to install.
    """
    global _variant
    if _variant is not None:
        return _variant
    variant = variant or os.environ.get("TOTEMS_VARIANT")
    if variant is None:
        variant = "cuda_ad_rgb" if _has_cuda() else "llvm_ad_rgb"
    if variant.startswith("llvm") and "DRJIT_LIBLLVM_PATH" not in os.environ:
        lib = _wheel_libllvm()
        if lib:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib

    import drjit as dr
    import mitsuba as mi

    try:
        mi.set_variant(variant)
    except Exception as exc:
        if variant.startswith("cuda"):
            return use("llvm_ad_rgb")
        raise BackendError(f"cannot start Mitsuba variant {variant}: {exc}") from None
    if variant.startswith("llvm"):
        try:
            version = tuple(dr.detail.llvm_version())
        except Exception:
            version = ()
        if not version:
            raise BackendError(
                "Dr.Jit found no libLLVM: `pip install karellen-llvm-core` "
                "or set DRJIT_LIBLLVM_PATH to a libLLVM 17 or newer")
        if version[0] in KNOWN_BAD_LLVM or version[0] < 11:
            raise BackendError(
                f"libLLVM {'.'.join(map(str, version))} crashes Dr.Jit; "
                "`pip install karellen-llvm-core` or set DRJIT_LIBLLVM_PATH "
                "to a libLLVM 17 or newer")
    threads = os.environ.get("TOTEMS_THREADS")
    if threads:
        dr.set_thread_count(int(threads))
    single_thread_blas()
    _variant = variant
    return variant


def single_thread_blas() -> None:
    """Keep every BLAS of the process (numpy's, scipy's, and OpenCV's, loaded later) on
    one thread.

    The fit's numpy work makes many tiny LAPACK calls (the view's Delaunay
    interpolation); a threaded OpenBLAS wakes its spinning threads for each, which
    beside Dr.Jit's own threads or another check made the stereo stage five times
    slower (docs/decisions.md, "fit: a check three times faster").
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")     # those loaded later (cv2's)
    import scipy.linalg  # noqa: F401  (scipy ships its own OpenBLAS: load it first)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")


@contextlib.contextmanager
def one_thread():
    """Run the block's Dr.Jit kernels on the calling thread alone (LLVM backend).

    A float scatter-add (the reverse of a plain gather or texture lookup) adds in the
    order the threads happen to run, so its last bits change from run to run; on one
    thread the order is fixed (the fit's own backward pass needs no such care: its
    grids' sums are in fixed point, exact on any number of threads,
    :mod:`inverse.exact_gather`). Queued kernels are finished before the pool changes
    size (resizing it under a running kernel crashes the process). On CUDA nothing
    changes.
    """
    dr = modules()[0]
    n = dr.thread_count()
    dr.sync_thread()
    dr.set_thread_count(1)
    try:
        yield
    finally:
        dr.sync_thread()
        dr.set_thread_count(n)


def modules():
    """``(drjit, mitsuba)`` with the variant chosen (:func:`use`): the way every function
    that needs them gets them, so that Dr.Jit never loads a libLLVM before :func:`use`."""
    use()
    import drjit
    import mitsuba

    return drjit, mitsuba


def describe() -> dict:
    """Versions of the backend pieces, for reports (``fit.json``, ``report.json``) and
    ``totems --version``; chooses the variant first, so it may be the first Dr.Jit use."""
    dr, mi = modules()
    info = {"variant": use(), "mitsuba": mi.__version__, "drjit": dr.__version__}
    if info["variant"].startswith("llvm"):
        info["llvm"] = ".".join(map(str, dr.detail.llvm_version()))
    return info


def aligned(array, dtype=np.float32) -> np.ndarray:
    """A C-contiguous copy of ``array`` as ``dtype`` whose buffer starts on 64 bytes.

    Dr.Jit's LLVM backend maps a contiguous numpy array without copying it and compiles
    each load as aligned or not by where the buffer happens to start. That enters the
    kernel's hash, so the same kernel fed a buffer of the other alignment misses the
    kernel cache and is compiled again (about 0.1 s a kernel).
    """
    a = np.asarray(array, dtype=dtype)
    buf = np.empty(a.nbytes + 64, np.uint8)
    start = (-buf.ctypes.data) % 64
    out = buf[start:start + a.nbytes].view(a.dtype).reshape(a.shape)
    out[...] = a
    return out


def upload(cls, array, dtype=np.float32):
    """``cls(array)``, a Dr.Jit array or tensor, from an :func:`aligned` copy of the
    numpy ``array``; for a 3-vector type ``array`` is (m, 3), one row a lane."""
    dr = modules()[0]
    a = np.asarray(array)
    if a.ndim == 2 and a.shape[1] == 3 and dr.size_v(cls) == 3:
        return cls(*[aligned(a[:, i], dtype) for i in range(3)])
    return cls(aligned(a, dtype))
