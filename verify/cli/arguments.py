"""Argument types of the ``totems`` command line: each parses one option's text or
says, in one line, what was expected (argparse then exits 2)."""

from __future__ import annotations

import argparse

__all__ = ["size", "size_any", "region", "point", "numbers", "positive", "ior", "engine",
           "scene_make", "plan", "tls"]


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


def numbers(n: int, what: str):
    """A type for ``n`` comma-separated numbers (``what`` names them in the error)."""
    def parse(text: str) -> tuple[float, ...]:
        try:
            values = tuple(float(x) for x in text.split(","))
        except ValueError:
            values = ()
        if len(values) != n or not all(map(_finite, values)):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return values
    return parse


def _finite(x: float) -> bool:
    return x == x and abs(x) != float("inf")


def ior(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not 1.0 < v < 4.0:
        raise argparse.ArgumentTypeError(f"the index of refraction must lie in (1, 4), "
                                         f"got {text}")
    return v


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


def plan(v) -> None:
    """The options of ``totems plan``: the camera, the key, the totems, the subject."""
    cam = v.add_argument_group("the camera (--photo, or --calib or --fov with --size)")
    cam.add_argument("--photo", default=None, metavar="SCENE",
                     help="a test photo's scene folder (image, calib.npy, totem_masks/, "
                          "totems.json): its camera, and its totems' poses from their "
                          "masks and the key")
    cam.add_argument("--calib", default=None, help="calib.npy from `totems calib`")
    cam.add_argument("--fov", type=positive(float), default=None, metavar="DEG",
                     help="horizontal field of view in degrees (no calib.npy)")
    cam.add_argument("--size", type=size, default=None, help="the photo's WxH in pixels")
    key = v.add_argument_group("the key (--key, or --radius and --ior; --photo: its own)")
    key.add_argument("--key", default=None, help="totems.json: radius (m) and ior")
    key.add_argument("--radius", type=positive(float), default=None, metavar="M",
                     help="the totems' radius in metres")
    key.add_argument("--ior", type=ior, default=None, metavar="N",
                     help="their index of refraction")
    v.add_argument("--totem", type=numbers(3, "U,V,DIST: a pixel and metres"),
                   action="append", default=None, metavar="U,V,DIST",
                   help="a totem where it will stand, once per totem: its centre's pixel "
                        "in the photo and its distance from the camera in metres")
    subject = v.add_mutually_exclusive_group(required=True)
    subject.add_argument("--subject-distance", type=float, default=None, metavar="M",
                         help="the subject, as a plane facing the camera this far away "
                              "(metres, along the optical axis)")
    subject.add_argument("--subject-plane", default=None, metavar="X,Y,Z,NX,NY,NZ",
                         type=numbers(6, "X,Y,Z,NX,NY,NZ: a point (m) and a normal"),
                         help="the subject's plane: a point and a normal, camera frame "
                              "(x right, y down, z forward; metres)")
    where = v.add_mutually_exclusive_group()
    where.add_argument("--subject-region", type=region, default=None, metavar="X,Y,W,H",
                       help="the subject's box in the photo, pixels (default: the frame "
                            "above the totems)")
    where.add_argument("--subject-mask", default=None, metavar="PNG",
                       help="the subject's region as a mask the photo's size (white)")
    v.add_argument("--out", default=None,
                   help="output folder (default plan-out; with --photo "
                        "SCENE/totems-out/plan)")
    v.add_argument("--no-move", action="store_true",
                   help="predict only: do not look for a move that widens the reach")


def tls(args) -> tuple[str | None, str | None, str | None]:
    """(CA file, certificate, key) of the ``engine`` options."""
    return args.tls_ca_file, args.tls_cert, args.tls_key
