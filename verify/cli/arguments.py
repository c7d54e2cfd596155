"""Argument types of the ``totems`` command line: each parses one option's text or
says, in one line, what was expected (argparse then exits 2)."""

from __future__ import annotations

import argparse

__all__ = ["size", "size_any", "region", "point", "positive", "engine", "tls"]


def size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be WxH, e.g. 640x480, got {text!r}")
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"size must be between 16 and 8192 px, got {text}")
    return w, h


def size_any(text: str) -> tuple[int, int]:
    try:
        a, b = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected COLSxROWS, e.g. 9x6, got {text!r}")
    return a, b


def region(text: str) -> tuple[int, int, int, int]:
    try:
        x, y, w, h = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"region must be x,y,w,h in pixels, got {text!r}")
    return x, y, w, h


def point(text: str) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected two numbers A,B, got {text!r}") \
            from None
    return a, b


def positive(kind):
    def parse(text):
        v = kind(text)
        if v <= 0:
            raise argparse.ArgumentTypeError(f"must be positive, got {text}")
        return v
    return parse


def engine(v) -> None:
    """Options of the verbs that run batches on Dask (bench, check DIR...):
    ``verify.batch.batch``."""
    v.add_argument("--jobs", type=positive(int), default=1,
                   help="photos run at once: workers of the local Dask cluster (default 1; "
                        "not used with --scheduler)")
    v.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on the existing Dask cluster of this scheduler (tcp://HOST:8786 "
                        "or tls://...); its workers must see the scene folders and --out at "
                        "the same paths and run the same totems")
    v.add_argument("--tls-ca-file", default=None, metavar="PEM",
                   help="with a tls:// scheduler: the CA certificate (else Dask's "
                        "configuration, distributed.comm.tls.*)")
    v.add_argument("--tls-cert", default=None, metavar="PEM",
                   help="with a tls:// scheduler: this client's certificate")
    v.add_argument("--tls-key", default=None, metavar="PEM",
                   help="with a tls:// scheduler: this client's private key")


def scene_make(v) -> None:
    """The options of ``totems scene make``."""
    from scenes.synthetic.placement import PLACEMENTS
    from scenes.synthetic.presets import PRESETS

    v.add_argument("out", help="new scene folder")
    v.add_argument("--preset", choices=PRESETS, default="box")
    v.add_argument("--seed", type=int, default=1)
    v.add_argument("--size", type=size, default=(640, 480), help="WxH (default 640x480)")
    v.add_argument("--totems", type=positive(int), default=None,
                   help="number of totems (default: the preset's: box and envmap 4, "
                        "the others drawn per seed)")
    v.add_argument("--placement", choices=PLACEMENTS, default=None,
                   help="how the totems stand: floating, resting on the floor, ground or "
                        "table, or on thin stands (default: the preset's; tabletop's rest)")
    v.add_argument("--spp", type=positive(int), default=None,
                   help="samples per pixel (default: the preset's)")
    v.add_argument("--camera", action="store_true",
                   help="a realistic camera: photon and read noise on the linear render, "
                        "before the sRGB tone curve (off: the render as it is)")


def tls(args) -> tuple[str | None, str | None, str | None]:
    """(CA file, certificate, key) of the ``engine`` options."""
    return args.tls_ca_file, args.tls_cert, args.tls_key
