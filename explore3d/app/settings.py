"""The one schema of run settings: :data:`RUN_OPTIONS` (every option of ``explore3d run``, a key of
its TOML ``--config`` and of a sweep's grid, with its checker), their defaults, and the
:class:`~explore3d.strategy.explore.ExploreConfig` they make.  The CLI, the TOML config and the
sweep all read it; light to import (``explore3d --help`` loads it)."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from explore3d.core.defaults import DEFAULT_A, MAX_A, SCENE_NAMES

MESH_FORMATS = ("obj", "stl", "ply", "off", "glb")  # = explore3d.app.export.MESH_FORMATS (not imported: heavy)


METHODS = ("exponential", "spherical")


MODES = ("3d", "planar")


#: = explore3d.app.export.DEFAULT_DENSITY_KG_M3 (not imported: heavy); tests check they agree.
DEFAULT_DENSITY_KG_M3 = 500.0


class UsageError(Exception):
    """Bad command-line or config input: exit code 2."""


class RunError(Exception):
    """A run that could not be completed: exit code 1."""


def _number(text, name: str) -> float:
    if isinstance(text, bool):
        raise UsageError(f"{name} must be a number; got {text!r}")
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be a number; got {text!r}") from None
    if not math.isfinite(v):
        raise UsageError(f"{name} must be finite; got {text!r}")
    return v


def _positive(name):
    def f(text):
        v = _number(text, name)
        if not v > 0:
            raise UsageError(f"{name} must be > 0; got {text!r}")
        return v
    f.__name__ = name  # argparse names the type in its own messages
    return f


def _coarseness(name):
    def f(text):
        v = _number(text, name)
        if not 0 < v <= MAX_A:
            raise UsageError(f"{name} must be > 0 and at most {MAX_A:g} (the inverse hull's coarseness: the paper "
                             f"uses 0.05-0.5, the default is {DEFAULT_A}); got {text!r}")
        return v
    f.__name__ = name
    return f


def _nonnegative(name):
    def f(text):
        v = _number(text, name)
        if not v >= 0:
            raise UsageError(f"{name} must be >= 0; got {text!r}")
        return v
    f.__name__ = name
    return f


def _int_min(name, lo=1):
    def f(text):
        if isinstance(text, bool) or isinstance(text, float):
            raise UsageError(f"{name} must be an integer >= {lo}; got {text!r}")
        try:
            v = int(text)
        except (TypeError, ValueError):
            raise UsageError(f"{name} must be an integer >= {lo}; got {text!r}") from None
        if v < lo:
            raise UsageError(f"{name} must be an integer >= {lo}; got {text!r}")
        return v
    f.__name__ = name
    return f


def _choice(name, choices):
    def f(text):
        v = str(text).lower()
        if v not in choices:
            raise UsageError(f"unknown {name} {text!r}; use one of {', '.join(choices)}")
        return v
    f.__name__ = name
    return f


def _int_any(name):
    def f(text):
        try:
            if isinstance(text, (bool, float)):
                raise ValueError
            return int(text)
        except (TypeError, ValueError):
            raise UsageError(f"{name} must be an integer; got {text!r}") from None
    f.__name__ = name
    return f


def _centre(text):
    t = str(text).strip().lower()
    if t in ("mean", "midrange"):
        return t
    parts = [p for p in t.replace(";", ",").split(",") if p.strip()]
    if len(parts) not in (2, 3):
        raise UsageError(f"--centre must be mean, midrange or x,y[,z] in metres; got {text!r}")
    return tuple(_number(p, "--centre coordinate") for p in parts)


def _point3(text):
    """The rough object centre for ``run``: "x,y,z" (or a TOML list of 3 numbers), metres."""
    parts = list(text) if isinstance(text, (list, tuple)) else \
        [p for p in str(text).replace(";", ",").split(",") if p.strip()]
    if len(parts) != 3:
        raise UsageError(f"--centre must be x,y,z in metres (the object's rough centre); got {text!r}")
    return tuple(_number(p, "--centre coordinate") for p in parts)


#: Options of ``run`` that a TOML config may set, with their checkers (flag name = key with '-').
RUN_OPTIONS = {
    "object": str,
    "out": str,
    "arm": str,
    "mode": _choice("mode", MODES),
    "directions": _int_min("--directions"),
    "attempts": _int_min("--attempts"),
    "a": _coarseness("--a"),
    "method": _choice("method", METHODS),
    "seed": _int_any("--seed"),
    # the seed of the simulated sensors' noise (explore3d.robot.sensing.SensorConfig.seed): one run is one
    # sample of the contact dynamics; figures are medians over these
    "noise_seed": _int_any("--noise-seed"),
    "jobs": _int_min("--jobs"),
    "format": _choice("format", MESH_FORMATS),
    "scale": _positive("--scale"),
    "size": _positive("--size"),
    # further ExploreConfig fields (TOML or flags)
    "offsets": _int_min("--offsets"),
    "angles": _int_min("--angles"),
    "mirrored": None,  # bool
    "base_step": _positive("--base_step"),
    "clearance": _positive("--clearance"),
    "n_along": _int_min("--n_along"),
    "n_height": _int_min("--n_height"),
    # the robot's rough bound of the object (default: from the mesh, explore3d.strategy.explore.rough_bound)
    "centre": _point3,
    "radius": _positive("--radius"),
    "no_pictures": None,  # bool
    # contact thickness: a known calibration (metres) or calibrate now on the 60 mm ball
    "face_offset": _nonnegative("--face-offset"),
    "calibrate": None,  # bool
    # evaluation after the run: the contact-quality figures (opt-in; "no_quality" is the default, kept
    # so older command lines and configs still work)
    "quality": None,  # bool
    "no_quality": None,  # bool
    # what the robot feels, and the simulator's contact margin
    "sensing": _choice("sensing", ("default", "ideal")),
    "collision_margin": _nonnegative("--collision-margin"),
    # what the hull is built from: contacts localised from the joint torques, or the paper's link faces
    "points": _choice("points", ("contacts", "links")),
    # rounds of probe wraps aimed at the estimate's least supported surface (3d; 0: none)
    "probes": _int_min("--probes", 0),
    # finger probes per round: the straight arm laid alongside unsupported surface in carved space
    "fingers": _int_min("--fingers", 0),
    # tip pokes per round: the tip brought along the estimate's inward normal onto unsupported surface
    "pokes": _int_min("--pokes", 0),
    # contour following: steps of 3 mm the tip slides each way after each poke's touch
    "slides": _int_min("--slides", 0),
    # how probe targets are ranked: the most volume at stake (area x distance to a contact) or the farthest
    # from every contact beyond a link length (the rule before issue 24)
    "probe_rank": _choice("probe_rank", ("stake", "distance")),
    # how each attempt encircles: the paper's straight sweep or its proposed curl-back
    "encircle": _choice("encircle", ("straight", "curl-back")),
    # the world: the paper's idealised one, or the object resting on a table (explore3d.world.scene)
    "scene": _choice("scene", SCENE_NAMES),
    # the contact detector: position errors only (stall, the paper's rule) or also every joint's external
    # torque (torque; explore3d.feeling.detect); default: the scene's
    "detector": _choice("detector", ("stall", "torque")),
    # evaluation after the run: this many grasps planned on each of the estimate, the truth, the estimate's
    # convex hull and an early estimate, executed on the truth (explore3d.app.grasp; 0: none)
    "grasp": _int_min("--grasp", 0),
    # keep the robot's logs and write them, with what an offline reconstruction needs, into this folder
    # (explore3d.app.offline; explore3d reconstruct --log DIR rebuilds the estimate from them)
    "record": str,
    # outputs
    "density": _positive("--density"),
    "height": _positive("--height"),
    # a 3D recording of the run for the rerun viewer, FILE.rrd (explore3d.app.rerun_view; the viz extra); not a
    # sweep key
    "rerun": str,
}


_BOOL_OPTIONS = ("mirrored", "no_pictures", "calibrate", "quality", "no_quality")


RUN_DEFAULTS = {"object": "cube", "arm": "default", "mode": "3d", "a": DEFAULT_A, "method": "exponential", "seed": 0,
                "format": "obj", "density": DEFAULT_DENSITY_KG_M3}


_EXPLORE_KEYS = ("mode", "directions", "attempts", "jobs", "offsets", "angles", "mirrored", "base_step",
                 "clearance", "n_along", "n_height", "face_offset", "points")


def _check_bool(v, name):
    if isinstance(v, bool):
        return v
    raise UsageError(f"{name} must be true or false; got {v!r}")


def read_toml_config(path) -> dict:
    """Options for ``run`` from a TOML file (keys as in :data:`RUN_OPTIONS`, '-' or '_'), checked."""
    from explore3d.core.validate import read_toml  # numpy: kept out of --help's start-up

    path = Path(path)
    try:
        data = read_toml(path, "config file", "--config")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    out = {}
    for k, v in data.items():
        key = k.replace("-", "_")
        if key not in RUN_OPTIONS:
            raise UsageError(f"unknown key {k!r} in config {path}; valid keys: {', '.join(sorted(RUN_OPTIONS))}")
        check = RUN_OPTIONS[key]
        if key in _BOOL_OPTIONS:
            out[key] = _check_bool(v, key)
        elif check is str:
            if not isinstance(v, str):
                raise UsageError(f"{k} in config {path} must be a string; got {v!r}")
            out[key] = v
        else:
            out[key] = check(v)
    if "scale" in out and "size" in out:
        raise UsageError(f"config {path} sets both scale and size; keep one")
    if out.get("quality") and out.get("no_quality"):
        raise UsageError(f"config {path} sets both quality and no_quality; keep one")
    return out


def resolve_run_options(args) -> dict:
    """Defaults < TOML config < flags, as a dict keyed like :data:`RUN_OPTIONS`."""
    opts = dict(RUN_DEFAULTS)
    if args.config:
        cfg = read_toml_config(args.config)
        if ("scale" in cfg or "size" in cfg) and (args.scale is not None or args.size is not None):
            cfg.pop("scale", None)
            cfg.pop("size", None)
        opts.update(cfg)
    for key in RUN_OPTIONS:
        v = getattr(args, key, None)
        if v is not None:
            opts[key] = v
    if getattr(args, "no_quality", None):  # a flag beats a config's quality = true
        opts["quality"] = False
    if not opts.get("out"):
        raise UsageError("run needs an output folder: pass --out DIR (or out = \"DIR\" in --config)")
    return opts


def explore_config(opts: dict):
    """The :class:`ExploreConfig` for resolved ``opts`` (unset fields keep ExploreConfig's defaults)."""
    from explore3d.core.settings import SimConfig  # these (numpy, the floors below) kept out of --help's start-up
    from explore3d.robot.sensing import SensorConfig
    from explore3d.strategy.active import ProbeConfig
    from explore3d.strategy.encircle import ControlConfig, CurlBack
    from explore3d.strategy.explore import ExploreConfig
    from explore3d.world.scene import scene_explore_config

    kw = {k: opts[k] for k in _EXPLORE_KEYS if k in opts}
    kw.setdefault("jobs", None)  # the command line spreads wraps over all cores unless told
    try:
        if opts.get("sensing") == "ideal":
            kw["sensors"] = SensorConfig.ideal()
        if opts.get("noise_seed") is not None:
            kw["sensors"] = dataclasses.replace(kw.get("sensors", SensorConfig()), seed=opts["noise_seed"])
        if opts.get("collision_margin") is not None:
            kw["sim"] = SimConfig(collision_margin=opts["collision_margin"])
        if any(opts.get(k) is not None for k in ("probes", "fingers", "pokes", "slides", "probe_rank")):
            probes = ProbeConfig() if opts.get("probes") is None else ProbeConfig(rounds=opts["probes"])
            if opts.get("probe_rank") == "distance":  # the former rule whole: its one-link floor too
                probes = dataclasses.replace(probes, rank="distance", min_distance_m=None)
            if opts.get("fingers") is not None:
                if not probes.rounds and opts["fingers"]:
                    raise ValueError("--fingers places finger probes in the rounds of probes: give --probes >= 1 "
                                     "(or leave --probes at its default)")
                probes = dataclasses.replace(probes, fingers=opts["fingers"])
            if opts.get("pokes") is not None:
                if not probes.rounds and opts["pokes"]:
                    raise ValueError("--pokes places tip pokes in the rounds of probes: give --probes >= 1 "
                                     "(or leave --probes at its default)")
                probes = dataclasses.replace(probes, pokes=opts["pokes"])
            if opts.get("slides") is not None:
                if opts["slides"] and not probes.pokes:
                    raise ValueError("--slides follows the tip after each poke: give --pokes >= 1")
                probes = dataclasses.replace(probes, slides=opts["slides"])
            kw["probes"] = probes if probes.rounds else None
        if opts.get("encircle") == "curl-back":
            kw["curl_back"] = CurlBack()
        if opts.get("scene", "ideal") != "ideal":
            return scene_explore_config(opts["scene"], spec=opts.get("arm") or "default", detector=opts.get("detector"),
                                        **kw)
        if opts.get("detector") is not None:
            kw["control"] = ControlConfig(detector=opts["detector"])
        return ExploreConfig(**kw)
    except (TypeError, ValueError) as exc:
        raise UsageError(str(exc)) from None


#: Settings a sweep's grid may sweep (explore3d.app.sweep), each an option of ``explore3d run`` (see ``explore3d run --help``).
SWEEP_KEYS = ("a", "angles", "arm", "attempts", "base_step", "clearance", "collision_margin", "detector", "directions",
              "encircle", "face_offset", "fingers", "grasp", "method", "mirrored", "mode", "n_along", "n_height", "noise_seed", "offsets",
              "points", "pokes", "probe_rank", "probes", "scene", "seed", "sensing", "size", "slides")
