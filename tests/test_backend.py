"""scenes/backend: the Dr.Jit variant and libLLVM are chosen at the first Dr.Jit use,
once, from any entry point, and never by importing a module of the package."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent

FRESH = textwrap.dedent("""
    import sys
    import inverse.fit.fit, inverse.fit.files, inverse.integrator, inverse.fit.outline
    import inverse.sphere, inverse.view.view, scenes.synthetic.render
    import scenes.tamper.tamper3d, verify.cli, verify.report.report
    assert "drjit" not in sys.modules and "mitsuba" not in sys.modules, \\
        "importing the package loaded Dr.Jit"

    import dataclasses
    import numpy as np
    from inverse.fit.fit import FitSettings, fit_scene
    from verify_cases import make_scene

    settings = FitSettings(density_res=(8, 12, 16), colour_res=(1, 15, 20),
                           stages=((1.0, 4),), render_samples=8, stereo=False)
    result = fit_scene(make_scene(), settings=settings, fixed_pose=True)
    assert np.isfinite(result.recon).all() and result.recon.shape == (240, 320, 3)

    from scenes import backend
    import mitsuba as mi
    assert mi.variant() == backend.use() and backend.use() in ("llvm_ad_rgb", "cuda_ad_rgb")
    if mi.variant().startswith("llvm"):
        import drjit as dr
        assert dr.detail.llvm_version()[0] not in backend.KNOWN_BAD_LLVM
    print("ok", mi.variant())
""")


@pytest.mark.slow
def test_a_fresh_process_fits_without_choosing_the_backend_first():
    done = subprocess.run([sys.executable, "-c", FRESH], cwd=TESTS, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("ok ")


def test_use_is_idempotent():
    from scenes import backend

    first = backend.use()
    assert backend.use() == first
    dr, mi = backend.modules()
    assert mi.variant() == first


def test_aligned_copies_start_on_64_bytes_and_keep_their_values():
    import numpy as np
    from scenes import backend

    buf = np.arange(1001, dtype=np.float64)
    for start in range(4):                    # numpy views of every alignment
        a = backend.aligned(buf[start:start + 997])
        assert a.ctypes.data % 64 == 0 and a.dtype == np.float32
        assert np.array_equal(a, buf[start:start + 997].astype(np.float32))
    rows = np.arange(30, dtype=np.float32).reshape(10, 3)
    _, mi = backend.modules()
    v = backend.upload(mi.Vector3f, rows)
    assert np.array_equal(np.asarray(v).T, rows)


def test_uploads_of_differently_aligned_arrays_reuse_one_kernel():
    """A mapped numpy buffer's alignment enters the kernel's hash: aligned uploads keep
    it the same, so the second call finds the kernel compiled for the first."""
    import numpy as np
    from scenes import backend

    dr, mi = backend.modules()
    buf = backend.aligned(np.random.default_rng(0).random(40_064))
    odd, even = buf[1:40_001], buf[16:40_016]       # 4 bytes past 64, and on 64
    fresh = float(np.random.default_rng().random())        # a kernel no cache holds yet

    def run(x):
        y = dr.exp(dr.sin(x * 1.25) * fresh) + 0.1137
        dr.eval(y)
        return [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        first = run(backend.upload(mi.Float, odd))
        second = run(backend.upload(mi.Float, even))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert first and second
    assert all(k["cache_hit"] for k in second)


def test_numpy_blas_runs_on_one_thread_once_the_backend_is_chosen():
    from threadpoolctl import threadpool_info

    from scenes import backend

    backend.use()
    import cv2  # noqa: F401  (its own OpenBLAS, loaded by verify after the fit)

    blas = [i for i in threadpool_info() if i["user_api"] == "blas"]
    assert any("opencv" in i["filepath"] for i in blas)
    assert blas and all(i["num_threads"] == 1 for i in blas)


def test_one_thread_makes_a_textures_gradient_the_same_on_every_run():
    """The reverse of a texture lookup is a float scatter-add: on one thread its sum has
    one order, so two backward passes agree to the last bit, and the gradient still sums
    to the lookups' weights (each lookup's trilinear weights sum to one)."""
    import numpy as np
    from scenes import backend

    dr, mi = backend.modules()
    rng = np.random.default_rng(0)
    points = rng.random((262_144, 3))
    weights = rng.standard_normal(262_144)
    grid = rng.standard_normal((12, 15, 20, 1))

    def gradient():
        tex = mi.Texture3f(backend.upload(mi.TensorXf, grid))
        x = tex.tensor()
        dr.enable_grad(x)
        tex.update_inplace()
        v = tex.eval(backend.upload(mi.Point3f, points))[0]
        loss = dr.sum(v * backend.upload(mi.Float, weights))
        with backend.one_thread():
            dr.backward(loss)
            g = dr.grad(x)
            dr.eval(g)
        return np.array(g.numpy(), np.float64)

    threads = dr.thread_count()
    first = gradient()
    assert all(np.array_equal(first, gradient()) for _ in range(3))
    assert dr.thread_count() == threads
    assert abs(first.sum() - weights.sum()) < 1e-5 * np.abs(weights).sum()
