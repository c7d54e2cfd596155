"""Run jingweim/totems run.py on CPU: how this log was made (see README.md).

Three changes, none to the NeRF or the totem optics: the CUDA default tensor type its
__main__ sets is not set; torchvision and tensorboard, which serve only its logging, are
stubbed; and its ray sampler for training is given all valid rays to draw from (with
n_rays its chunked search concatenates the whole xs array when the first chunk has too
few valid rays, so ys and xs disagree and rays miss the sphere: NaN).

    python run_cpu.py --config config.txt [run.py flags]      # src/ holds run*.py
"""
import sys
import types

import numpy as np
import torch

sys.path.insert(0, "src")
torch.set_num_threads(1)
tv = types.ModuleType("torchvision")
tv.utils = types.SimpleNamespace(make_grid=lambda *a, **k: None)
sys.modules["torchvision"] = tv
tb = types.ModuleType("torch.utils.tensorboard")


class SummaryWriter:
    def __init__(self, *a, **k):
        pass

    def add_scalar(self, *a, **k):
        pass

    add_image = add_scalar


tb.SummaryWriter = SummaryWriter
sys.modules["torch.utils.tensorboard"] = tb

import run  # noqa: E402

torch.autograd.set_detect_anomaly(False)   # run_nerf_helpers turns it on at import (slow)
_rays = run.get_totem_rays_numpy


def _sampled(args, data, totem_idx, totem_pos, n_rays=None):
    """n_rays drawn at random from all valid rays of the totem."""
    o, d, ys, xs, rgb = _rays(args, data, totem_idx, totem_pos, n_rays=None)
    if n_rays:
        pick = np.random.permutation(len(ys))[:n_rays]
        assert len(pick) >= n_rays
        o, d, ys, xs, rgb = o[pick], d[pick], ys[pick], xs[pick], rgb[pick]
    return o, d, ys, xs, rgb


run.get_totem_rays_numpy = _sampled
args = run.config_parser().parse_args()
if args.render_only:
    run.test(args)
elif args.detect_only:
    run.detect(args)
else:
    run.train(args)
