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
    import inverse.fit, inverse.fit_files, inverse.integrator, inverse.outline
    import inverse.sphere, inverse.view, scenes.render, scenes.tamper3d, verify.cli
    import verify.report
    assert "drjit" not in sys.modules and "mitsuba" not in sys.modules, \\
        "importing the package loaded Dr.Jit"

    import dataclasses
    import numpy as np
    from inverse.fit import FitSettings, fit_scene
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
