"""The placement study (issue 62): how much of a person-sized subject the totems' reach
covers, by how the totems are placed, and how near ``totems plan`` comes to the truth.

    python benchmarks/placement_study.py [--quick] [--json FILE]

Each placement is a scene description (the format of ``scenes/synthetic/render.py``)
built here: a floor, a person-sized board (0.5 x 1.7 m; or a body 0.3 m deep) standing
on it ``D`` m away (3-6 m), a wall 2 m behind it, and the totems; the camera 1.2 m above
the floor, pitched 12 degrees down, 640 x 480, 60 degrees across (the working resolution
the verdict judges at). The truth's reach is traced by Mitsuba
(:func:`scenes.synthetic.trace.truth_reach`: what the totems truly see, occlusion and
all); the subject is its pixels (those a totem hides count as outside the reach). The
plan is :func:`scenes.plan.plan.make_plan` of the same centres and key over the same
pixels, twice: with the board's own plane, and with the plane a user would give,
``--subject-distance`` (facing the camera at the board centre's depth).

A placement: ``n`` totems of radius ``R`` (IoR 1.5) in a row ``spread`` of the frame's
width wide at their depth, ``share`` times the subject's distance from the camera,
``height`` metres above the floor (``"rest"``: lying on it), ``stagger`` metres
alternately nearer and farther, the row ``offset`` metres right of the board, each
totem drawn about its place by ``jitter`` metres; a crate may stand between the totems
and the subject (``clutter``). Sections printed:

1. the factors one at a time from a base (four 5 cm totems, 60 % of the width, half the
   subject's distance, 0.5 m above the floor, a subject at 4 m), from a tight row (25 %
   of the width), and a resting row's distance;
2. two sets of random placements (set A, seeds 0-59: where the guide's rules and the
   plan's search were chosen; set B, seeds 1000-1059: drawn after), each with the median
   |plan - truth| share, Spearman's rank correlation and the placements off by more
   than 10 points, by kind; and the rule of thumb's constant chosen on set A, checked
   on set B;
3. four 5 cm totems for a person at 4 m over a grid of spread, share, height and
   stagger, by the truth; and from a tight row, where the plan's suggested moves lead
   (each checked against the truth);
4. ``totems plan``'s wall time as a user runs it (a fresh process, the move search on).
"""

from __future__ import annotations

import argparse
import itertools
import json
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from scenes import backend, camera
from scenes.plan.plan import make_plan
from scenes.plan.predict import fronto_plane, subject_plane
from scenes.synthetic.preset_parts import affine, pitch_rotation
from scenes.synthetic.trace import truth_reach

SIZE = (640, 480)
FOV = 60.0
CAM_HEIGHT = 1.2        # metres above the floor
PITCH = 12.0            # degrees down
BOARD = (0.5, 1.7)      # width, height, metres
DEPTH = 0.3             # a body's depth, metres
BACK = 2.0              # the wall, metres behind the board
IOR = 1.5
K = camera.intrinsics(*SIZE, FOV)
ROOM = pitch_rotation(PITCH)          # room coordinates (y down, z forward) -> camera


@dataclass(frozen=True)
class Placement:
    n: int = 4
    radius: float = 0.05
    spread: float = 0.6         # share of the frame's width the row spans
    share: float = 0.5          # the totems' distance over the subject's
    height: float | str = 0.5   # metres above the floor, or "rest"
    stagger: float = 0.0        # metres, alternately nearer and farther
    offset: float = 0.0         # metres, the row's centre right of the board's
    subject: float = 4.0        # the board's distance, metres
    board_x: float = 0.0        # the board's centre, metres right of the camera's axis
    jitter: float = 0.0         # metres, each totem drawn about its place
    body: bool = False          # the subject a 0.3 m deep box, not a flat board
    clutter: bool = False       # a 0.4 m crate on the floor between totems and subject
    seed: int = 0


def cam(p) -> np.ndarray:
    """A room point (x right, y down from the camera's height, z forward) in the camera
    frame."""
    return ROOM @ np.asarray(p, np.float64)


def rectangle(centre, half_x, half_y) -> list:
    """``to_world`` of a rectangle at room point ``centre`` spanning the room vectors
    ``half_x``, ``half_y``, its front towards the camera."""
    a, b = cam(half_x), cam(half_y)
    n = np.cross(a, b)
    n /= np.linalg.norm(n)
    if n @ -cam(centre) < 0:
        n = -n
    return affine(np.stack([a, b, n], 1), cam(centre)).tolist()


def centres(p: Placement) -> np.ndarray:
    """The totems' centres, camera frame (metres): a row across the frame at
    ``share * subject`` m, spanning ``spread`` of its width there."""
    rng = np.random.default_rng(p.seed)
    z = p.share * p.subject
    half = z * np.tan(np.radians(FOV / 2)) - 2.5 * p.radius   # the frame's half width
    xs = p.offset + p.spread * half * np.linspace(-1, 1, p.n) if p.n > 1 \
        else np.array([p.offset])
    y = CAM_HEIGHT - (p.radius if p.height == "rest" else float(p.height))
    out = []
    for j, x in enumerate(xs):
        dz = p.stagger * (1 if j % 2 else -1) if p.n > 1 else 0.0
        jit = rng.normal(0, p.jitter, 3) * np.array([1, 0 if p.height == "rest" else 1, 1])
        out.append(cam([x + jit[0], y + jit[1], z + dz + jit[2]]))
    return np.array(out)


def describe(p: Placement) -> dict:
    def paint(g):
        return {"type": "diffuse", "rgb": [g, g, g]}

    D, (bw, bh) = p.subject, BOARD
    objects = [
        {"id": 0, "name": "floor", "kind": "rectangle", "material": paint(0.3),
         "to_world": rectangle([0, CAM_HEIGHT, D], [30, 0, 0], [0, 0, 30])},
        {"id": 1, "name": "wall", "kind": "rectangle", "material": paint(0.5),
         "to_world": rectangle([0, CAM_HEIGHT - 5, D + BACK], [30, 0, 0], [0, 5, 0])},
        {"id": 2, "name": "board", "kind": "rectangle", "material": paint(0.7),
         "to_world": rectangle([p.board_x, CAM_HEIGHT - bh / 2, D], [bw / 2, 0, 0],
                               [0, bh / 2, 0])}]
    if p.body:                  # the board as the front of a body 0.3 m deep
        objects[2] = {"id": 2, "name": "body", "kind": "cube", "material": paint(0.7),
                      "to_world": affine(ROOM @ np.diag([bw / 2, bh / 2, DEPTH / 2]),
                                         cam([p.board_x, CAM_HEIGHT - bh / 2,
                                              D + DEPTH / 2])).tolist()}
    if p.clutter:               # a crate on the floor, between the totems and the subject
        rng = np.random.default_rng(p.seed + 7)
        z = D - rng.uniform(0.6, 1.2)
        x = p.board_x + rng.uniform(-0.5, 0.5)
        objects.append({"id": 3, "name": "crate", "kind": "cube", "material": paint(0.4),
                        "to_world": affine(ROOM * 0.2, cam([x, CAM_HEIGHT - 0.2, z]))
                        .tolist()})
    totems = [{"center": c.tolist(), "radius": p.radius, "ior": IOR} for c in centres(p)]
    return {"format": 1, "size": list(SIZE), "K": K.tolist(), "envmap": None,
            "lights": [], "objects": objects, "totems": totems}


def board_plane(p: Placement):
    return subject_plane(cam([p.board_x, CAM_HEIGHT - BOARD[1] / 2, p.subject]),
                         cam([0, 0, -1.0]))


def board_pixels(p: Placement) -> np.ndarray:
    """(H, W) bool: the subject's pixels, the totems left out (the pixels a totem hides
    then count as outside the reach); traced, as a crate may hide part of it."""
    from scenes.synthetic.trace import camera_points, tracer

    desc = describe(p)
    return camera_points(desc, tracer(desc, totems=False))[2] == 2


def fits(p: Placement) -> bool:
    """The placement can be photographed: every totem wholly in the frame, none
    overlapping another or the board (the plan's own check)."""
    from scenes.errors import BadInput
    from scenes.plan.predict import check_placement

    try:
        check_placement(K, SIZE, centres(p), np.full(p.n, p.radius), board_plane(p))
    except BadInput:
        return False
    return True


def measure(p: Placement) -> dict:
    """The board's share in the truth's reach and in the plan's, with the board's plane
    and with a fronto-parallel plane at its centre's depth."""
    region = board_pixels(p)
    t0 = time.perf_counter()
    reach, _ = truth_reach(describe(p))
    t1 = time.perf_counter()
    C, R = centres(p), np.full(p.n, p.radius)
    plan = make_plan(K, SIZE, C, R, np.full(p.n, IOR), board_plane(p), region=region,
                     suggest=False)
    t2 = time.perf_counter()
    depth = float(board_plane(p).point[2])
    fronto = make_plan(K, SIZE, C, R, np.full(p.n, IOR), fronto_plane(depth),
                       region=region, suggest=False)
    return {**asdict(p), "truth": float(reach.in_reach()[region].mean()),
            "seen_two": float(((reach.n_totems >= 2) & ~reach.excluded)[region].mean()),
            "plan": plan.share, "plan_fronto": fronto.share, "margin": margin(p),
            "truth_s": t1 - t0, "plan_s": t2 - t1}


RULE = 3.2
"""The rule of thumb's constant (docs/placement.md): two totems of radius R establish a
subject D - L metres behind them when their images lie at least RULE (D - L) / R pixels
apart in a 640 px wide photo (ray spacing about 1.2 times a ball lens's paraxial one,
times the parallax of 4 the rule asks for)."""


def margin(p: Placement, rule: float = RULE) -> float:
    """The best pair's image separation over what the rule of thumb asks for (over 1:
    the rule says the subject is in reach)."""
    C = centres(p)
    uv = camera.project(K, C)
    D = float(board_plane(p).point[2])
    best = 0.0
    for i in range(p.n):
        for j in range(i + 1, p.n):
            gap = D - 0.5 * (C[i, 2] + C[j, 2])
            need = rule * gap / p.radius * SIZE[0] / 640
            best = max(best, float(np.linalg.norm(uv[i] - uv[j])) / need)
    return best


# --------------------------------------------------------------------------- sections

BASE = Placement()
TIGHT = replace(BASE, spread=0.25)
FACTORS = {
    "n": [2, 3, 4, 6, 8],
    "spread": [0.1, 0.2, 0.3, 0.4, 0.6, 0.8, 1.0],
    "share": [0.2, 0.35, 0.5, 0.65, 0.8],
    "height": ["rest", 0.25, 0.5, 0.8],
    "radius": [0.03, 0.04, 0.05, 0.065, 0.08],
    "subject": [3.0, 4.0, 5.0, 6.0],
    "stagger": [0.0, 0.25, 0.5],
}
RESTING = replace(BASE, height="rest", spread=0.8)


def _line(r) -> str:
    return (f"truth {100 * r['truth']:5.1f} %   plan {100 * r['plan']:5.1f} %   plan "
            f"(distance) {100 * r['plan_fronto']:5.1f} %   two see {100 * r['seen_two']:5.1f} "
            f"%   rule margin {r['margin']:4.2f}")


def factor_rows(quick: bool) -> list[dict]:
    """Each factor swept from BASE and from TIGHT; the resting row's share swept too."""
    rows = []
    sweeps = [("base", BASE, n, v) for n, v in FACTORS.items()] + \
        [("tight", TIGHT, n, v) for n, v in FACTORS.items() if n != "spread"] + \
        [("resting", RESTING, "share", [0.3, 0.4, 0.5, 0.6, 0.7, 0.8])]
    for base_name, base, name, values in sweeps:
        for value in (values[::2] if quick else values):
            p = replace(base, **{name: value})
            tag = f"  {base_name:7s} {name:8s} {str(value):5s}"
            if not fits(p):
                rows.append({**asdict(p), "base": base_name, "factor": name, "fits": False})
                print(f"{tag}  does not fit in the frame", flush=True)
                continue
            rows.append({**measure(p), "base": base_name, "factor": name, "fits": True})
            print(f"{tag}  {_line(rows[-1])}", flush=True)
    return rows


def random_placement(seed: int) -> Placement:
    rng = np.random.default_rng(seed)
    return Placement(
        n=int(rng.integers(2, 9)), radius=float(rng.uniform(0.03, 0.08)),
        spread=float(rng.uniform(0.05, 1.0)), share=float(rng.uniform(0.2, 0.85)),
        height="rest" if rng.random() < 0.35 else float(rng.uniform(0.2, 1.0)),
        stagger=float(rng.choice([0.0, rng.uniform(0.1, 0.6)])),
        offset=float(rng.uniform(-0.5, 0.5)), subject=float(rng.uniform(3.0, 6.0)),
        board_x=float(rng.uniform(-0.6, 0.6)), jitter=float(rng.uniform(0.0, 0.1)),
        body=bool(rng.random() < 0.5), clutter=bool(rng.random() < 0.25), seed=seed)


def random_rows(seeds) -> list[dict]:
    """One placement per seed: the first of its draws (seed * 100 + k) that fits."""
    rows = []
    for s in seeds:
        for k in range(100):
            p = random_placement(s * 100 + k)
            if fits(p):
                rows.append(measure(p))
                break
    return rows


def spearman(a, b) -> float:
    from scipy.stats import spearmanr

    return float(spearmanr(a, b).statistic)


def agreement(rows, key="plan") -> str:
    t = np.array([r["truth"] for r in rows])
    q = np.array([r[key] for r in rows])
    err = np.abs(q - t)
    return (f"n {len(rows)}, median |plan - truth| {100 * np.median(err):.1f} points "
            f"(mean {100 * err.mean():.1f}, 90th pct {100 * np.percentile(err, 90):.1f}, "
            f"max {100 * err.max():.1f}), over 10 points {int((err > 0.1).sum())}, "
            f"Spearman {spearman(q, t):.3f}, bias {100 * (q - t).mean():+.1f}")


def rule_constant(rows) -> float:
    """The rule of thumb's constant that best tells, on ``rows``, the placements whose
    subject is mostly in the truth's reach (over half) from the others: the one with
    the fewest errors, midway along the best range."""
    best, at = None, []
    for c in np.arange(1.0, 8.01, 0.1):
        wrong = sum((r["margin"] * RULE / c >= 1) != (r["truth"] > 0.5) for r in rows)
        if best is None or wrong < best:
            best, at = wrong, [c]
        elif wrong == best:
            at.append(c)
    return float(np.median(at))


def rule_errors(rows, c: float) -> str:
    said = np.array([r["margin"] * RULE / c >= 1 for r in rows])
    true = np.array([r["truth"] > 0.5 for r in rows])
    return (f"rule with constant {c:.1f}: right on {int((said == true).sum())} of "
            f"{len(rows)} (says covered, is not: {int((said & ~true).sum())}; says not, "
            f"is: {int((~said & true).sum())})")


def best_grid(quick: bool) -> list[dict]:
    grid = dict(spread=[0.3, 0.5, 0.7, 1.0], share=[0.3, 0.5, 0.7],
                height=["rest", 0.5, 1.0], stagger=[0.0, 0.4])
    if quick:
        grid = dict(spread=[0.7, 1.0], share=[0.5, 0.7], height=["rest", 0.5],
                    stagger=[0.0])
    rows = []
    for values in itertools.product(*grid.values()):
        p = replace(BASE, **dict(zip(grid, values)))
        if fits(p):
            rows.append(measure(p))
    return rows


def follow_moves(start: Placement, steps: int = 3) -> list[dict]:
    """From ``start``, apply the plan's suggested move ``steps`` times (each from the
    placement the last one left, with the subject as the user gives it: a distance),
    and measure the truth's reach after each."""
    from scenes.plan.suggest import best_move

    C = centres(start)
    R, ior = np.full(start.n, start.radius), np.full(start.n, IOR)
    region = board_pixels(start)
    plane = fronto_plane(float(board_plane(start).point[2]))
    desc = describe(start)
    out = []
    for k in range(steps + 1):
        desc["totems"] = [{"center": c.tolist(), "radius": start.radius, "ior": IOR}
                          for c in C]
        reach, _ = truth_reach(desc)
        plan = make_plan(K, SIZE, C, R, ior, plane, region=region, suggest=False)
        out.append({"step": k, "truth": float(reach.in_reach()[region].mean()),
                    "plan": plan.share, "centers": C.round(3).tolist()})
        if k == steps:
            break
        m = best_move(K, SIZE, C, R, ior, plane, region)
        if m is None:
            break
        C = C.copy()
        C[m.totem] = m.center
    return out


def cli_seconds(p: Placement, runs: int = 3) -> list[float]:
    """``totems plan`` of placement ``p`` in a fresh process, the move search on."""
    uv = camera.project(K, centres(p))
    dist = np.linalg.norm(centres(p), axis=1)
    args = [sys.executable, "-m", "verify.cli", "plan", "--fov", str(FOV), "--size",
            f"{SIZE[0]}x{SIZE[1]}", "--radius", str(p.radius), "--ior", str(IOR),
            "--subject-distance", f"{board_plane(p).point[2]:.3f}", "--quiet",
            "--out", "/tmp/placement-study-plan"]
    for (u, v), d in zip(uv, dist):
        args += ["--totem", f"{u:.1f},{v:.1f},{d:.3f}"]
    out = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(args, check=True)
        out.append(time.perf_counter() - t0)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer placements (a smoke run)")
    ap.add_argument("--json", type=Path, default=None, help="write every row here")
    args = ap.parse_args(argv)
    backend.use()
    t_start = time.perf_counter()
    out = {}
    print("1. the factors one at a time, from a base (4 totems of 5 cm, 60 % of the "
          "width, half the subject's distance, 0.5 m up, a board at 4 m), from a tight "
          "row (25 % of the width), and a resting row's distance", flush=True)
    out["factors"] = factor_rows(args.quick)
    fitted = [r for r in out["factors"] if r["fits"]]
    print(f"   plan against truth on these: {agreement(fitted)}")
    print(f"   with the subject as a distance: {agreement(fitted, 'plan_fronto')}")
    k = 12 if args.quick else 60
    for name, seeds in (("A", range(0, k)), ("B", range(1000, 1000 + k))):
        rows = random_rows(seeds)
        out[f"set_{name}"] = rows
        print(f"2. set {name} (random placements, seeds {seeds.start}-{seeds.stop - 1}): "
              f"{agreement(rows)}", flush=True)
        print(f"   with the subject as a distance: {agreement(rows, 'plan_fronto')}")
        for what, sel in (("flat boards", [r for r in rows if not r["body"]]),
                          ("bodies 0.3 m deep", [r for r in rows if r["body"]]),
                          ("a crate between", [r for r in rows if r["clutter"]]),
                          ("resting", [r for r in rows if r["height"] == "rest"])):
            if len(sel) > 2:
                print(f"   {what}: {agreement(sel, 'plan_fronto')}")
        truth = np.array([r["truth"] for r in rows])
        print(f"   truth's share: median {100 * np.median(truth):.0f} %, "
              f"{int((truth >= 0.8).sum())} of {len(rows)} at 80 % or more, "
              f"{int((truth <= 0.2).sum())} at 20 % or less")
    c = rule_constant(out["set_A"])
    out["rule_constant"] = c
    print(f"   the rule of thumb, its constant chosen on set A: "
          f"{rule_errors(out['set_A'], c)}")
    print(f"   on set B: {rule_errors(out['set_B'], c)}")
    print("3. four 5 cm totems, a person at 4 m: the best of a grid, by the truth",
          flush=True)
    grid = best_grid(args.quick)
    out["grid"] = grid
    ranked = sorted(grid, key=lambda r: -r["truth"])
    for r in ranked[:5] + ranked[-3:]:
        print(f"   spread {r['spread']:.1f} share {r['share']:.1f} height "
              f"{str(r['height']):4s} stagger {r['stagger']:.1f}: truth "
              f"{100 * r['truth']:.1f} %, plan {100 * r['plan']:.1f} %")
    print(f"   on the grid: {agreement(grid)}; {sum(r['truth'] >= 0.8 for r in grid)} of "
          f"{len(grid)} at 80 % or more")
    moves = follow_moves(replace(BASE, spread=0.15))
    out["moves"] = moves
    for m in moves:
        print(f"   the plan's moves from a tight row, step {m['step']}: truth "
              f"{100 * m['truth']:.1f} %, plan {100 * m['plan']:.1f} %")
    secs = cli_seconds(BASE) + cli_seconds(replace(BASE, n=8))
    out["cli_seconds"] = secs
    print(f"4. totems plan, a fresh process, the move search on (4 then 8 totems): "
          f"{', '.join(f'{s:.1f}' for s in secs)} s")
    lib = [r["plan_s"] for r in out["set_B"]]
    print(f"   make_plan without the search, in process: median {np.median(lib):.2f} s; "
          f"the truth's trace: median {np.median([r['truth_s'] for r in out['set_B']]):.2f} s")
    print(f"(the study took {time.perf_counter() - t_start:.0f} s)")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
