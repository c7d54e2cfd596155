"""The three sets of photos, named in one place, with fixed and disjoint seed ranges.

``development``   for trying ideas: anything may be tuned on it.
``calibration``   for the verdict's thresholds only: untouched photos over every preset
                  and channel (box and envmap seeds 11-18 are the held-out scenes the
                  thresholds were first calibrated on).
``benchmark``     for the README's figures only: untouched photos pristine, at JPEG 75 and
                  in one other channel each (turning through them, so every preset meets
                  every channel: about two hours of fits here, not the seven of every
                  channel for every photo), every manipulation (but ``rekey``)
                  pristine and at JPEG 75, the totems study (box and envmap seeds 1-5
                  are the standard set of the figures so far).

So that no figure is reported on what it was tuned on, a preset's seed belongs to one
set at most (``RESERVED`` seeds to none): :func:`check_disjoint` refuses an overlap and
runs when this module is imported. A photo is named ``<preset>-<seed>`` (the untouched
scene), ``-<n>totems`` for the totems study, ``-resting`` for totems resting on the floor
or ground (``RESTING``: box, outdoor, window), ``-<kind>`` when manipulated and
``+<channel>`` when recaptured (``totems recapture``); the pristine photos keep the
standard set's names. Channels are :class:`scenes.channel.channel.Channel` settings. Each
set also holds scenes rendered by Blender's Cycles on seeds of its own (``CYCLES``;
``make_set.py --cycles`` builds them through ``benchmarks/cycles/``, and recaptures them
in ``CYCLES_CHANNELS``).
"""

from __future__ import annotations

from dataclasses import dataclass

from scenes.synthetic.presets import PRESETS
from scenes.tamper.tamper import KINDS, TOTEM_KINDS

__all__ = ["CHANNELS", "SEEDS", "CYCLES", "CYCLES_CHANNELS", "RESERVED", "Recipe", "RECIPES",
           "Photo", "SETS", "SCENE_KINDS", "TOTEM_EDITS", "check_disjoint", "seeds_of", "owner",
           "photos"]

UNTOUCHED = "none"
SCENE_KINDS = tuple(k for k in KINDS if k not in TOTEM_KINDS)
"""The manipulations before issue 61's forgers of the totems (the standard set's)."""
TOTEM_EDITS = ("totem-retouch", "consistent-paste", "erase-everywhere")
"""The forgeries that edit the totems too, made of each seed with its own seed. ``rekey``
is not among them: its key error is a setting to sweep (issue 61, the key's strength),
not a photo per seed."""

# name -> scenes.channel.channel.Channel fields (the camera's and the messenger's steps)
CHANNELS = {
    "pristine": {},
    "jpeg90": {"jpeg": (90,)},
    "jpeg75": {"jpeg": (75,)},
    "noise2": {"noise": 2.0},                       # sigma 2/255
    "blur0.7": {"blur": 0.7},                       # defocus, sigma in pixels
    "tone": {"exposure": 1.1, "gamma": 0.9},
    "resize480": {"long_side": 480, "jpeg": (85,)},  # a messenger: 640 -> 480 px, JPEG 85
}
RECAPTURED = tuple(c for c in CHANNELS if c != "pristine")

# set -> preset -> seeds
SEEDS = {
    "development": {p: range(31, 36) for p in PRESETS},
    "calibration": {p: range(11, 19) for p in PRESETS},
    "benchmark": {p: range(1, 6) for p in PRESETS},
}
# set -> the seeds of its Cycles-rendered scenes (benchmarks/cycles/; one scene a seed,
# its kind drawn from the seed), their 2D edits and whether a removal is rendered.
# Seeds 101-111 were looked at while the generator was built: development's.
CYCLES = {
    "development": (range(101, 112), ("color", "splice"), True),
    "calibration": (range(201, 209), (), False),
    "benchmark": (range(301, 306), ("color", "splice"), True),
}
# set -> the channels every one of its Cycles photos is also recaptured in (the benchmark
# judges its edits pristine and at JPEG 75, as its Mitsuba recipes do)
CYCLES_CHANNELS = {"benchmark": ("jpeg75",)}
# seeds used before the sets existed, kept out of every set
RESERVED = {"validation of the thresholds (README, 2026-12)":
            {"box": range(21, 26), "envmap": range(21, 26)}}


@dataclass(frozen=True)
class Recipe:
    """Which photos a set makes of each of its seeds.

    kinds : "none" (the untouched photo) and manipulations (``scenes.tamper.tamper.KINDS``;
        made with the kind's defaults and the photo's seed).
    channels : each photo in every one of these, or, with ``rotate`` = k, in
        k of them, turning through the list from seed to seed (so every channel meets
        every preset without every photo in every channel).
    presets, seeds : a subset of the set's (None: all).
    n_totems : the number of totems (None: the preset's).
    placement : how the totems stand (``scenes.synthetic.placement``; None: the preset's).
    """
    kinds: tuple = (UNTOUCHED,)
    channels: tuple = ("pristine",)
    rotate: int | None = None
    presets: tuple | None = None
    seeds: range | None = None
    n_totems: int | None = None
    placement: str | None = None


RESTING = ("box", "outdoor", "window")
"""The presets whose totems also rest on the floor or the ground in every set (tabletop's
always rest; envmap's floor is box's)."""

RECIPES = {
    "development": (Recipe(kinds=(UNTOUCHED,) + SCENE_KINDS + TOTEM_EDITS),
                    Recipe(channels=("jpeg75", "noise2", "resize480")),
                    Recipe(kinds=(UNTOUCHED, "color", "splice"), presets=RESTING,
                           placement="resting")),
    "calibration": (Recipe(),
                    Recipe(channels=RECAPTURED, rotate=2),
                    Recipe(presets=RESTING, placement="resting"),
                    Recipe(channels=RECAPTURED, rotate=1, presets=RESTING,
                           placement="resting")),
    "benchmark": (Recipe(channels=("pristine", "jpeg75")),
                  Recipe(channels=tuple(c for c in RECAPTURED if c != "jpeg75"), rotate=1),
                  Recipe(kinds=SCENE_KINDS, channels=("pristine", "jpeg75")),
                  Recipe(kinds=TOTEM_EDITS, channels=("pristine", "jpeg75")),
                  Recipe(presets=("box",), seeds=range(1, 3), n_totems=2),
                  Recipe(presets=("box",), seeds=range(1, 3), n_totems=6),
                  Recipe(kinds=(UNTOUCHED, "color", "splice"), channels=("pristine", "jpeg75"),
                         presets=RESTING, placement="resting")),
}
SETS = tuple(SEEDS)


@dataclass(frozen=True, order=True)
class Photo:
    """One photo of a set: the scene (preset, seed, totems, their placement), the
    manipulation, the channel."""
    preset: str
    seed: int
    kind: str = UNTOUCHED
    channel: str = "pristine"
    n_totems: int | None = None
    placement: str | None = None

    @property
    def scene(self) -> str:
        """Folder name of the untouched, pristine scene it is made from."""
        return f"{self.preset}-{self.seed}" + \
            ("" if self.n_totems is None else f"-{self.n_totems}totems") + \
            ("" if self.placement is None else f"-{self.placement}")

    @property
    def source(self) -> str:
        """Folder name of the pristine photo it is recaptured from (its own if
        pristine)."""
        return self.scene + ("" if self.kind == UNTOUCHED else f"-{self.kind}")

    @property
    def name(self) -> str:
        return self.source + ("" if self.channel == "pristine" else f"+{self.channel}")


def check_disjoint(seeds=None, reserved=None) -> None:
    """Raise ValueError when a preset's seed lies in two sets (or a set and
    ``RESERVED``), naming them; the Cycles scenes count as the preset "cycles"."""
    groups = {name: {**by_preset, **({"cycles": CYCLES[name][0]} if name in CYCLES
                                     and seeds is None else {})}
              for name, by_preset in (SEEDS if seeds is None else seeds).items()}
    groups.update(RESERVED if reserved is None else reserved)
    owner: dict = {}
    for group, by_preset in groups.items():
        for preset, rng in by_preset.items():
            for s in rng:
                other = owner.setdefault((preset, s), group)
                if other != group:
                    raise ValueError(f"{preset} seed {s} is in both {other!r} and "
                                     f"{group!r}: a set's seeds must be its own")


def seeds_of(set_name: str, preset: str):
    """The set's seeds of a preset; a Cycles scene's preset (``cycles-<kind>``) takes
    the set's Cycles seeds (``CYCLES``)."""
    if preset.startswith("cycles-"):
        return CYCLES.get(set_name, ((),))[0]
    return SEEDS[set_name].get(preset, ())


def owner(preset: str, seed: int) -> str | None:
    """The set a preset's seed belongs to (None: to none)."""
    return next((s for s in SEEDS if seed in seeds_of(s, preset)), None)


def photos(name: str) -> list[Photo]:
    """Every photo of the set ``name``, sorted."""
    if name not in RECIPES:
        raise ValueError(f"unknown set {name!r}; use one of {', '.join(SETS)}")
    out = set()
    for r in RECIPES[name]:
        for i, (preset, seed) in enumerate(
                (p, s) for p in (r.presets or PRESETS)
                for s in (r.seeds or SEEDS[name][p])):
            if seed not in SEEDS[name][preset]:
                raise ValueError(f"{name}: {preset} seed {seed} is not the set's")
            channels = r.channels if r.rotate is None else \
                tuple(r.channels[(i * r.rotate + k) % len(r.channels)]
                      for k in range(r.rotate))
            out.update(Photo(preset, seed, kind, channel, r.n_totems, r.placement)
                       for kind in r.kinds for channel in channels)
    return sorted(out, key=lambda p: (p.preset, p.seed, str(p.n_totems),
                                      str(p.placement), p.kind, p.channel))


check_disjoint()
