"""Command line: ``explore3d run|reconstruct|evaluate|compare|sweep|sweep-report|table1|arm|objects``.

The parser produces the same dataclasses the Python API takes (:class:`ExploreConfig`,
:class:`ArmSpec`); ``main(argv)`` returns an exit code and never raises or prints a traceback:

* 0: success;
* 1: a failed run (missing/unreadable/empty/non-mesh/open input file, no contacts, unwritable
  output); a one-line ``explore3d: error: ...`` on stderr;
* 2: a usage error (unknown option or value, non-numeric, out of range, unknown object, arm or
  format, bad TOML config); the same one-line form;
* 130: interrupted (Ctrl-C, SIGINT, at any moment): ``explore3d: error: interrupted``, no
  traceback from the command or its worker processes; ``run`` leaves its output folder as it was
  (:func:`explore3d.app.report.run_and_report`: all or nothing).

Heavy modules (numpy, trimesh, pybullet, matplotlib) are imported inside the commands, so
``explore3d --help`` is instant.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import logging
import math
import os
import signal
import sys
import tempfile
import threading
from pathlib import Path

from explore3d.app.settings import (
    DEFAULT_DENSITY_KG_M3,
    MESH_FORMATS,
    RUN_OPTIONS,
    SWEEP_KEYS,
    RunError,
    UsageError,
    _centre,
    _int_min,
    _number,
    _positive,
    explore_config,
    resolve_run_options,
)
from explore3d.core.defaults import DEFAULT_A, ESTIMATOR_NAMES, MAX_A, SCENE_NAMES
from explore3d.core.interrupt import INTERRUPTED, check_interrupt, sigint_handler
from explore3d.core.io import atomic_write_text, json_text
from explore3d.core.quiet import STDERR, quiet_c_output

PROG = "explore3d"

log = logging.getLogger("explore3d.app.cli")






class _Parser(argparse.ArgumentParser):
    """ArgumentParser that raises :class:`UsageError` instead of printing usage and exiting."""

    def error(self, message):
        raise UsageError(f"{message} (see '{self.prog} --help')")


# --- value checkers (used for flags and TOML values alike) -----------------------------------------

























# --- parser --------------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="Explore an object with a simulated blind arm and reconstruct its shape "
                                       "by the inverse convex hull.")
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    r = sub.add_parser("run", help="explore an object, reconstruct it, measure the error, write results",
                       description="Explore OBJECT (built-in name, mesh file or pybullet_data:NAME), reconstruct "
                                   "its shape and write report.json, the estimate mesh, estimate.urdf, points.ply "
                                   "and pictures into --out.  Flags override --config.")
    r.add_argument("object", nargs="?", default=None, help="built-in name, mesh path or pybullet_data:NAME (default: cube)")
    r.add_argument("--out", help="output folder (required, here or in --config)")
    r.add_argument("--arm", help="built-in arm (paper, default) or a URDF written by 'explore3d arm'")
    r.add_argument("--mode", type=RUN_OPTIONS["mode"], help="3d (default) or planar")
    r.add_argument("--directions", type=RUN_OPTIONS["directions"], help="approach directions / plane normals (default: ExploreConfig)")
    r.add_argument("--attempts", type=RUN_OPTIONS["attempts"], help="attempts per wrap")
    r.add_argument("--offsets", type=RUN_OPTIONS["offsets"], help="3d: planes per normal")
    r.add_argument("--angles", type=RUN_OPTIONS["angles"], help="3d: approach angles per plane")
    r.add_argument("--a", type=RUN_OPTIONS["a"], help=f"inverse-hull coarseness in (0, {MAX_A:g}] (default {DEFAULT_A}, as explore3d.run)")
    r.add_argument("--method", type=RUN_OPTIONS["method"], help="exponential (default) or spherical")
    r.add_argument("--seed", type=RUN_OPTIONS["seed"], help="seed of the error-measure surface samples (default 0)")
    r.add_argument("--noise-seed", dest="noise_seed", type=RUN_OPTIONS["noise_seed"],
                   help="seed of the simulated sensors' noise (default 0; each wrap draws from (seed, wrap index))")
    r.add_argument("--jobs", type=RUN_OPTIONS["jobs"], help="worker processes >= 1 (default: all cores; results do not depend on it)")
    r.add_argument("--config", help="TOML file with the same option names (object, out, arm, mode, ...)")
    r.add_argument("--format", type=RUN_OPTIONS["format"], help=f"estimate mesh format: {', '.join(MESH_FORMATS)} (default obj)")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--scale", type=RUN_OPTIONS["scale"], help="scale the object by this factor")
    g.add_argument("--size", type=RUN_OPTIONS["size"], help="rescale the object so its longest side is SIZE metres")
    r.add_argument("--centre", type=RUN_OPTIONS["centre"],
                   help="x,y,z: the object's rough centre the robot is told, metres (default: its bounding-box centre)")
    r.add_argument("--radius", type=RUN_OPTIONS["radius"],
                   help="the object's rough bounding radius the robot is told, metres (default: 1.05 x the largest "
                        "vertex distance from the centre); contact points beyond it are dropped")
    r.add_argument("--no-pictures", dest="no_pictures", action="store_true", default=None,
                   help="skip the PNG pictures (faster)")
    r.add_argument("--rerun", metavar="FILE.rrd",
                   help="also write a 3D recording of the run for the rerun viewer (the arm's links, detections, "
                        "contacts, swept free space and the estimate after each round, on a timeline per wrap, and "
                        "the truth); open it with 'rerun FILE.rrd' (needs: pip install -e \".[viz]\")")
    q_ = r.add_mutually_exclusive_group()
    q_.add_argument("--quality", dest="quality", action="store_true", default=None,
                    help="also compute the contact-quality figures (evaluation only, after the run, against the "
                         "true mesh; records the joint trajectories; slow: about 30 s more on the cube, "
                         "minutes on large meshes); their time is report.json's timings.quality_s")
    q_.add_argument("--no-quality", dest="no_quality", action="store_true", default=None,
                    help="no contact-quality figures (the default; kept for older command lines)")
    r.add_argument("--grasp", type=RUN_OPTIONS["grasp"], metavar="N",
                   help="3d: after the run, plan N grasps on each of the estimate, the truth, the estimate's convex "
                        "hull and an early estimate and execute them on the truth, as 'explore3d grasp' does "
                        "(evaluation only; default 0: none); the rates go into report.json's grasp entry")
    r.add_argument("--record", metavar="DIR",
                   help="keep the robot's logs (every command and joint reading) and write them into DIR with the "
                        "arm, the contact band and the rough bound: 'explore3d reconstruct --log DIR' rebuilds the "
                        "estimate from them alone (docs/robot-interface.md)")
    r.add_argument("--sensing", type=RUN_OPTIONS["sensing"],
                   help="what the servos report: default (4096-count encoders, 1 mN m torque resolution and noise, "
                        "one step of delay) or ideal (exact, no delay)")
    r.add_argument("--collision-margin", dest="collision_margin", type=RUN_OPTIONS["collision_margin"],
                   help="the simulator's contact margin on the object and the links, metres (default 0.0003)")
    r.add_argument("--points", type=RUN_OPTIONS["points"],
                   help="what the hull is built from: contacts (default: localised from the joint torques, "
                        "points.ply with their normals and uncertainty) or links (the paper's rule: the faces of "
                        "the links whose sweep detected a contact)")
    r.add_argument("--probes", type=RUN_OPTIONS["probes"], metavar="ROUNDS",
                   help="3d: at most this many rounds of probe wraps through the estimate's least supported "
                        "surface after the first wraps (default 3; 0: none)")
    r.add_argument("--fingers", type=RUN_OPTIONS["fingers"], metavar="N",
                   help="3d: finger probes per round of probes: the straight arm laid alongside unsupported "
                        "surface through space the estimate leaves empty, then swept onto it (default 12; 0: none)")
    r.add_argument("--pokes", type=RUN_OPTIONS["pokes"], metavar="N",
                   help="3d: tip pokes per round of probes: the tip, the distal links bent into a hook, brought "
                        "along the estimate's inward normal onto unsupported surface (default 12; 0: none)")
    r.add_argument("--slides", type=RUN_OPTIONS["slides"], metavar="N",
                   help="3d: contour following after each poke's touch: the tip slides N steps of 3 mm each way "
                        "along the surface, a contact read at each (default 0: none; needs pokes, on by default)")
    r.add_argument("--probe-rank", dest="probe_rank", type=RUN_OPTIONS["probe_rank"],
                   help="3d: how probe targets are chosen: stake (default: the most volume the estimate could still "
                        "have wrong, area x distance to the nearest contact) or distance (the farthest from every "
                        "contact beyond a link length, the rule before issue 24)")
    r.add_argument("--scene", type=RUN_OPTIONS["scene"],
                   help="ideal (default: the object fixed, floating, frictionless, exact model, world reset per wrap) "
                        "or table (resting on a table with weight and friction 0.5, 5%% model mass error, one "
                        "persistent world, horizontal and table-clearing wraps, gentle sweeps)")
    r.add_argument("--detector", type=RUN_OPTIONS["detector"],
                   help="stall (the paper's rule: a joint falls behind its reference) or torque (also every joint's "
                        "external torque, the arm's model against its motor torques: a touch anywhere shows on the "
                        "joints before it); default: the scene's (ideal: stall; table: see docs/scene.md)")
    r.add_argument("--encircle", type=RUN_OPTIONS["encircle"],
                   help="straight (default: every joint sweeps the straight chain beyond it, the paper's method) "
                        "or curl-back (after the first contact the chain beyond a few straight links curls away "
                        "from the object and unravels as contacts are found, the paper's Future Work)")
    r.add_argument("--density", type=RUN_OPTIONS["density"],
                   help=f"density of the estimate body in estimate.urdf, kg/m^3 (default {DEFAULT_DENSITY_KG_M3:g})")
    r.add_argument("--height", type=RUN_OPTIONS["height"],
                   help="planar runs: extrude the estimate polygon this many metres, centred on the arm's plane "
                        "(default: the arm's sensed height band, the plane's z +- half the link height)")
    t_ = r.add_mutually_exclusive_group()
    t_.add_argument("--face-offset", dest="face_offset", type=RUN_OPTIONS["face_offset"],
                    help="calibrated contact thickness, metres: link faces are pushed this far towards the "
                         "object (default 0)")
    t_.add_argument("--calibrate", dest="calibrate", action="store_true", default=None,
                    help="first calibrate the contact thickness on a known 60 mm ball (never the object under "
                         "test) with the same settings, then use it (about doubles the run time)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress display and no result line")
    r.add_argument("-v", "--verbose", action="count", default=0, help="log what runs (-vv: debug)")
    r.set_defaults(func=cmd_run)

    c = sub.add_parser("reconstruct", help="inverse convex hull of a point file, or a run rebuilt from its logs",
                       description="Reconstruct a shape from POINTS (PLY/XYZ, metres) by the inverse convex hull. "
                                   "3D points give a mesh (format from the --out suffix); points with z = 0 "
                                   "(planar runs) give a polygon: --out X.json, or a mesh extruded by --height.")
    c.add_argument("points", nargs="?", default=None, help="point file (PLY, XYZ, or anything trimesh loads)")
    c.add_argument("--log", metavar="DIR", default=None,
                   help="instead of POINTS: the folder 'explore3d run ... --record DIR' wrote; the run's estimate is "
                        "rebuilt from its robot logs alone (the controller replayed, the contacts localised, the free "
                        "space swept and the hull built as the run did)")
    c.add_argument("--readings", action="store_true",
                   help="with --log or --bag: read the logs with no controller in the loop (sweeps, detections and "
                        "settled readings found in the recorded references and readings), as for another "
                        "controller's logs; without it the controller is replayed against them (exact for "
                        "explore3d's own)")
    c.add_argument("--arm", default=None,
                   help="with --bag --readings: the bag is another controller's, of this arm (built-in name or URDF); "
                        "give --band, --centre X,Y,Z and --radius too")
    c.add_argument("--band", metavar="FILE", default=None,
                   help="with --arm: the contact band (a run's report.json, or JSON with swept_rad and other_rad)")
    c.add_argument("--joint-states", dest="joint_states", default="/joint_states",
                   help="with --arm: the sensor_msgs/JointState topic of angles, velocities, efforts (default "
                        "/joint_states)")
    c.add_argument("--references", default="/explore3d/joint_command",
                   help="with --arm: the JointState topic whose position holds the position references")
    c.add_argument("--base-pose", dest="base_pose", default="/explore3d/base_pose",
                   help="with --arm: the geometry_msgs/PoseStamped topic of the base pose, one per motion")
    c.add_argument("--joint-names", dest="joint_names", default=None,
                   help="with --arm: the arm's joints in chain order, comma-separated (default joint0,joint1,...)")
    c.add_argument("--bag", metavar="DIR", default=None,
                   help="instead of POINTS: the ROS 2 bag of a recording (DIR/bag of 'explore3d run ... --record "
                        "DIR'; sqlite3 or MCAP, read with rosbags); the run's estimate is rebuilt from it as --log does")
    c.add_argument("--out", required=True, help="output mesh (.obj .stl .ply .off .glb) or polygon .json")
    c.add_argument("--a", type=RUN_OPTIONS["a"], default=DEFAULT_A, help=f"coarseness in (0, {MAX_A:g}] (default {DEFAULT_A}, as run)")
    c.add_argument("--method", type=RUN_OPTIONS["method"], default="exponential")
    c.add_argument("--free-space", metavar="NPZ", default=None,
                   help="carve the 3D hull with the space the arm swept through (the free_space.npz a run wrote), "
                        "as the run did")
    c.add_argument("--centre", type=_centre, default="midrange",
                   help="mean, midrange (default) or x,y[,z] in metres (2D points use x,y)")
    c.add_argument("--radius", type=_positive("--radius"),
                   help="drop points farther than this many metres from --centre (as 'run' does with its rough "
                        "bound: report.json's config.centre_m and config.radius_m)")
    c.add_argument("--height", type=_positive("--height"),
                   help="2D points: extrude the polygon this many metres, centred on the points' plane")
    c.add_argument("--estimator", choices=ESTIMATOR_NAMES, default="inverse-hull",
                   help="3D points: the paper's inverse hull about --centre (default; measured best on the arm's "
                        "contacts, BENCHMARKS.md), the convex hull, inverse hulls about several interior centres "
                        "united, or an implicit surface fitted to the points and their normals (points.ply's nx, "
                        "ny, nz); each carved by --free-space")
    c.set_defaults(func=cmd_reconstruct)

    e = sub.add_parser("evaluate", help="error measures of an estimate against the truth",
                       description="Compare ESTIMATE with TRUTH: closed meshes (files, or built-in names for "
                                   "TRUTH) or 2D polygons given as JSON lists of [x, y] (metres).")
    e.add_argument("estimate")
    e.add_argument("truth")
    e.add_argument("--json", action="store_true", help="print JSON only")
    e.set_defaults(func=cmd_evaluate)

    k = sub.add_parser("compare", help="link points, localised contacts and an ideal skin on the same sweeps",
                       description="Explore OBJECT once; print the error, IoU, Chamfer distance and surface coverage "
                                   "(within 3 and 6 mm of a point) of the paper's link points, of the contacts "
                                   "localised from the joint torques (the pipeline's default) and of an ideal skin "
                                   "(every contact point PyBullet reports at the same readings; evaluation only), "
                                   "and the localisation against the skin (in-plane and 3D distance, precision and "
                                   "recall within 3 mm).")
    k.add_argument("object", help="built-in name, mesh path or pybullet_data:NAME")
    k.add_argument("--arm", default="default", help="built-in arm or a URDF written by 'explore3d arm'")
    k.add_argument("--mode", type=RUN_OPTIONS["mode"], help="3d (default) or planar")
    k.add_argument("--directions", type=RUN_OPTIONS["directions"], help="approach directions / plane normals")
    k.add_argument("--attempts", type=RUN_OPTIONS["attempts"], help="attempts per wrap")
    k.add_argument("--angles", type=RUN_OPTIONS["angles"], help="3d: approach angles per plane")
    k.add_argument("--probes", type=RUN_OPTIONS["probes"], metavar="ROUNDS",
                   help="3d: rounds of probe wraps aimed at the estimate (default 3; 0: none)")
    k.add_argument("--fingers", type=RUN_OPTIONS["fingers"], metavar="N",
                   help="3d: finger probes per round of probes (default 12; 0: none)")
    k.add_argument("--pokes", type=RUN_OPTIONS["pokes"], metavar="N",
                   help="3d: tip pokes per round of probes (default 12; 0: none)")
    k.add_argument("--slides", type=RUN_OPTIONS["slides"], metavar="N",
                   help="3d: contour-following steps each way after each poke (default 0: none)")
    k.add_argument("--encircle", type=RUN_OPTIONS["encircle"], help="straight (default) or curl-back")
    k.add_argument("--no-free-space", dest="no_free_space", action="store_true",
                   help="3d: neither record the swept space nor carve with it (the paper's hull of the straight "
                        "sweeps; implies --probes 0)")
    k.add_argument("--a", type=RUN_OPTIONS["a"], default=DEFAULT_A, help=f"inverse-hull coarseness (default {DEFAULT_A})")
    k.add_argument("--size", type=RUN_OPTIONS["size"], help="rescale the object so its longest side is SIZE metres")
    k.add_argument("--jobs", type=RUN_OPTIONS["jobs"], help="worker processes for the exploration (default: all cores)")
    k.add_argument("--json", action="store_true", help="print JSON only")
    k.set_defaults(func=cmd_compare)

    t = sub.add_parser("table1", help="the paper's Table 1 next to ours",
                       description="Reproduce Table 1 of the paper (explore3d.app.table1.table1_rows).")
    t.add_argument("--json", action="store_true", help="print JSON")
    t.add_argument("--a", type=RUN_OPTIONS["a"], help=f"inverse-hull coarseness in (0, {MAX_A:g}] (default: table1_rows' own, 0.2)")
    t.add_argument("--seed", type=RUN_OPTIONS["seed"], help="seed of the simulated many-links case")
    t.add_argument("--3d", dest="three_d", action="store_true",
                   help="also the default arm's 3D volume errors on the cube, cylinder and sphere, with and "
                        "without the contact thickness calibrated on a 60 mm ball (several minutes)")
    t.add_argument("--jobs", type=RUN_OPTIONS["jobs"], help="worker processes for --3d (default: all cores)")
    t.set_defaults(func=cmd_table1)

    b = sub.add_parser("band", help="write an arm's contact band: measured on its twin, or from its own logs",
                       description="Write the contact band of --arm as JSON (swept_rad, other_rad, provenance): "
                                   "measured on the arm's simulated twin with the default settings (cached), or with "
                                   "--log DIR from the arm's own contact-free calibration logs (RobotLog .npz files: "
                                   "free motion of every joint).  'explore3d reconstruct --band FILE' reads it.")
    b.add_argument("--arm", default="default", help="built-in arm or URDF (default: default)")
    b.add_argument("--log", metavar="DIR", default=None,
                   help="a folder of the arm's contact-free calibration logs (*.npz, RobotLog files)")
    b.add_argument("--planar", action="store_true", help="the twin's band for planar runs")
    b.add_argument("--out", required=True, help="JSON file to write")
    b.set_defaults(func=cmd_band)

    a = sub.add_parser("arm", help="write an arm URDF",
                       description="Write a chain arm URDF (explore3d.arm.urdf.write_arm_urdf); fields default to --base.")
    a.add_argument("--out", required=True, help="URDF file to write")
    a.add_argument("--base", default="default", help="arm to start from: paper, default or a URDF (default: default)")
    a.add_argument("--name")
    a.add_argument("--n-links", type=_int_min("--n-links"))
    for fld in ("link_length", "link_width", "link_height", "link_mass", "max_torque", "base_size"):
        a.add_argument("--" + fld.replace("_", "-"), type=_positive("--" + fld.replace("_", "-")),
                       help="kg" if fld == "link_mass" else ("N m" if fld == "max_torque" else "metres"))
    a.add_argument("--joint-lower", type=lambda s: _number(s, "--joint-lower"), help="rad, < 0")
    a.add_argument("--joint-upper", type=lambda s: _number(s, "--joint-upper"), help="rad, > 0")
    a.set_defaults(func=cmd_arm)

    w = sub.add_parser("sweep", help="run every object x settings combination once, rows in an SQLite database",
                       description="Run every combination of OBJECTS (built-in names, mesh files, globs, "
                                   "pybullet_data:PATTERN) and the --grid settings once, as 'explore3d run' would "
                                   "(no pictures), storing each result as it finishes in OUT/sweep.db and its estimate "
                                   "in OUT/runs/<key>/.  Run the same command again to finish a killed sweep: only "
                                   "the combinations without a row run (and runs lost to a killed or vanished "
                                   "worker).  Failed runs (also crashed workers) are stored with a one-line reason.  "
                                   "One sweep at a time per --out folder (a second one refuses to start).  Settings: "
                                   + ", ".join(SWEEP_KEYS) + ".  Exit codes: 0 at least one combination is stored "
                                   "as ok (failures, if any, are counted in one line on stderr); 1 every combination "
                                   "failed, another sweep runs on --out, --out holds a sweep.db that is not a "
                                   "sweep's, or --out cannot be written; 2 a usage error; 130 interrupted.")
    w.add_argument("objects", nargs="+", help="built-in names, mesh files, globs or pybullet_data:PATTERN (quote globs)")
    w.add_argument("--out", required=True, help="output folder (sweep.db, runs/, truths/)")
    w.add_argument("--size", type=RUN_OPTIONS["size"], help="rescale every object so its longest side is SIZE metres")
    w.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="a swept setting and its values (repeat for more; one value fixes a setting), e.g. "
                        "--grid a=0.02,0.05,0.1 --grid arm=default,paper")
    w.add_argument("--grid-file", help="TOML file of KEY = value or KEY = [values] (--grid flags override its keys)")
    w.add_argument("--workers", type=_int_min("--workers"), default=1, help="runs at once (default 1)")
    w.add_argument("--jobs-per-run", dest="jobs_per_run", type=_int_min("--jobs-per-run"), default=1,
                   help="processes per run for its wraps (default 1; results do not depend on it)")
    w.add_argument("--ray", action="store_true",
                   help="run on Ray: a local Ray with --workers x --jobs-per-run CPUs, or the cluster at "
                        "--ray-address / $RAY_ADDRESS (pip install 'explore3d[ray]')")
    w.add_argument("--ray-address", help="an existing Ray cluster (implies --ray)")
    w.add_argument("--retry-failed", action="store_true", help="also run the combinations stored as failures again")
    w.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar, no summary line (failures are still counted in one line on stderr)")
    w.set_defaults(func=cmd_sweep)

    sr = sub.add_parser("sweep-report", help="tables, a plot and an HTML page of a sweep",
                        description="Write report.md and report.csv (per object and setting: error, IoU, Chamfer, "
                                    "time, failures), errors.png (error against each swept setting) and report.html "
                                    "(the table with a thumbnail per run: the estimate coloured by its signed "
                                    "distance to the truth, mm) for the sweep in DIR.  DIR is only read (its "
                                    "sweep.db opened read-only).  Exit codes: 0 written; 1 DIR holds no sweep, its "
                                    "sweep.db is not a sweep's, or the report cannot be written; 2 a usage error.")
    sr.add_argument("folder", metavar="DIR", help="the --out folder of 'explore3d sweep'")
    sr.add_argument("--out", help="folder for the report (default: DIR/report; give another for a read-only DIR)")
    sr.add_argument("--no-thumbnails", dest="thumbnails", action="store_false", help="skip the thumbnails (faster)")
    sr.set_defaults(func=cmd_sweep_report)

    g = sub.add_parser("grasp", help="plan grasps on a run's estimate, execute them on the true object, count",
                       description="Plan --n antipodal parallel-jaw grasps on RUN_DIR's estimate, on the true mesh, "
                                   "on the estimate's convex hull and on an early estimate (the first 8 wraps), "
                                   "execute each on the true object resting on a table in PyBullet, and add the "
                                   "success rates (95% Wilson intervals) to RUN_DIR/report.json; also writes "
                                   "grasps.json and grasps.png.")
    g.add_argument("run_dir", help="a folder 'explore3d run' wrote (3D)")
    g.add_argument("--n", type=_int_min("--n"), default=20, help="grasps planned on each mesh (default 20)")
    g.add_argument("--seed", type=_int_min("--seed", 0), default=0, help="planner seed (default 0)")
    g.add_argument("--friction", type=_positive("--friction"), default=None,
                   help="pad friction coefficient, the planner's friction cone and the execution's (default 0.8)")
    g.add_argument("--grip-force", dest="grip_force", type=_positive("--grip-force"), default=None,
                   help="force each finger presses with, N (default 20)")
    g.add_argument("--density", type=_positive("--density"), default=None,
                   help="the true object's density in the execution, kg/m^3 (default 500)")
    g.add_argument("--no-pictures", action="store_true", help="no grasps.png")
    g.set_defaults(func=cmd_grasp)

    o = sub.add_parser("objects", help="list the built-in objects with their sizes",
                       description="List the built-in objects (extents in mm, volume in cm^3).")
    o.add_argument("--json", action="store_true")
    o.set_defaults(func=cmd_objects)
    for cmd in sub.choices.values():  # every command: -q (no progress display) and -v (log, -vv: debug)
        have = {o for a in cmd._actions for o in a.option_strings}
        if "-q" not in have:
            cmd.add_argument("-q", "--quiet", action="store_true", help="no progress display")
        if "-v" not in have:
            cmd.add_argument("-v", "--verbose", action="count", default=0, help="log what runs (-vv: debug)")
    return p


def _version() -> str:
    from explore3d import __version__  # start-up: kept out of explore3d --help's

    return __version__


# --- run -----------------------------------------------------------------------------------------





def _check_object_name(spec: str) -> None:
    from explore3d.world.objects import BUILTIN_OBJECTS  # start-up: kept out of explore3d --help's

    if spec in BUILTIN_OBJECTS or spec.startswith("pybullet_data:"):
        return
    p = Path(spec)
    if not p.exists() and not p.suffix and "/" not in spec and "\\" not in spec:
        raise UsageError(f"unknown object {spec!r}; use a built-in name ({', '.join(BUILTIN_OBJECTS)}), "
                         "a mesh file or pybullet_data:NAME (see 'explore3d objects')")


def _prepare_out_dir(out: Path) -> None:
    """Create ``out`` and check it is writable, before any simulation is spent."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise RunError(f"cannot write to output folder {out} ({exc.strerror or exc}); "
                       "choose a writable --out folder") from None


def _dump(obj) -> str:
    return json_text(obj)


def cmd_run(args) -> int:
    """Parse -> configuration dataclasses -> :func:`explore3d.app.report.run_and_report` -> one line."""
    opts = resolve_run_options(args)
    _setup_logging(args.verbose)
    out = Path(opts["out"])
    _check_object_name(opts["object"])
    config = explore_config(opts)
    if opts.get("calibrate") and "face_offset" in opts:
        raise UsageError("--calibrate and --face-offset exclude each other: pass one")
    if (opts.get("calibrate") or opts.get("face_offset")) and config.points != "links":
        raise UsageError("--calibrate and --face-offset correct the paper's link points; the localised contacts (the "
                         "default) lie on the links' surfaces already: add --points links, or drop them")
    if opts.get("record"):
        record_dir = Path(opts["record"])
        if record_dir.exists() and not record_dir.is_dir():
            raise UsageError(f"--record {record_dir} is a file; give a folder for the recording")
        if record_dir.resolve() == out.resolve():
            raise UsageError(f"--record {record_dir} is the --out folder; give the recording a folder of its own "
                             f"(e.g. {out / 'recording'})")
        config = dataclasses.replace(config, record=True)
    if opts.get("grasp") and config.mode != "3d":
        raise UsageError(f"--grasp plans grasps on a 3D estimate; this run is --mode {config.mode}: drop --grasp or "
                         "run --mode 3d")

    with quiet_c_output():  # PyBullet's banners (import, connect, solver switch, renderer)
        from explore3d.app.pipeline import NoContactError, ReconstructionError, check_run_inputs
        from explore3d.app.report import OutputConfig, run_and_report
        from explore3d.arm.urdf import load_arm  # start-up: kept out of explore3d --help's

        try:
            spec = load_arm(opts["arm"])
            output = OutputConfig(fmt=opts["format"], pictures=not opts.get("no_pictures", False),
                                  quality=bool(opts.get("quality", False)), density=opts["density"],
                                  height=opts.get("height"))
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        if opts.get("rerun"):  # the file and the optional extra checked before any simulation
            from explore3d.app.rerun_view import check_recording_path, require_rerun  # start-up: as above

            try:
                check_recording_path(opts["rerun"], out)
                require_rerun()
            except ValueError as exc:
                raise UsageError(str(exc)) from None
            except FileNotFoundError as exc:
                raise RunError(str(exc)) from None
        _prepare_out_dir(out)

        import numpy as np  # start-up: kept out of explore3d --help's

        from explore3d.world.objects import load_object

        mesh = load_object(opts["object"], scale=opts.get("scale"), size=opts.get("size"))
        check_interrupt()  # a Ctrl-C an import swallowed (trimesh's optional imports catch everything)
        log.info("object %s: extents %s m", opts["object"], np.round(mesh.extents, 4).tolist())
        check_run_inputs(mesh, spec, config, opts["a"], opts["method"], opts.get("centre"), opts.get("radius"))

        from explore3d.app.progress import RUN_STEPS, Progress  # start-up: kept out of explore3d --help's

        steps = RUN_STEPS + ("recording",) * bool(opts.get("record")) + ("grasping",) * bool(opts.get("grasp")) + (
            "3D recording",) * bool(opts.get("rerun"))
        with Progress(steps, enabled=not args.quiet, prog=PROG) as progress:
            try:
                res, report = run_and_report(
                    mesh, opts["arm"], config, out, output=output, a=opts["a"], method=opts["method"], seed=opts["seed"],
                    centre=opts.get("centre"), radius=opts.get("radius"), calibrate=bool(opts.get("calibrate")),
                    progress=progress, object_name=opts["object"],
                    source={"scale": opts.get("scale"), "size": opts.get("size")})
            except NoContactError:
                raise RunError("no contacts at all: the arm never touched the object; check the object size and rough "
                               "bound against the arm (--size, --arm, --centre, --radius) or add --directions/--attempts "
                               f"(report written to {out / 'report.json'})") from None
            except ReconstructionError as exc:
                raise RunError(f"reconstruction failed: {exc} (report written to {out / 'report.json'})") from None
            if opts.get("record"):
                progress.step("recording")
                from explore3d.app.offline import recording_dict, write_recording  # start-up: kept out of --help's
                from explore3d.app.rosbag import write_bag  # start-up: kept out of --help's

                write_recording(res.exploration, opts["record"], res.centre, res.radius, opts["a"], opts["method"])
                write_bag(recording_dict(res.exploration, res.centre, res.radius, opts["a"], opts["method"]),
                          res.exploration.logs, Path(opts["record"]) / "bag")
            if opts.get("grasp"):
                progress.step("grasping")
                from explore3d.app.grasp import GraspConfig, grasp_run  # start-up: kept out of --help's

                grasp = grasp_run(out, GraspConfig(n=opts["grasp"]), pictures=not opts.get("no_pictures", False),
                                  truth=mesh)
            if opts.get("rerun"):
                progress.step("3D recording")
                from explore3d.app.rerun_view import write_rerun  # start-up: kept out of --help's

                try:
                    write_rerun(opts["rerun"], res, mesh if res.setup is None else res.truth, a=opts["a"],
                                method=opts["method"])
                except OSError as exc:
                    raise RunError(f"cannot write the rerun recording {opts['rerun']} ({exc.strerror or exc}); the run's "
                                   f"files are in {out}") from None
            progress.finish()
    ex, err = res.exploration, res.error
    if not args.quiet:
        print(f"{opts['object']}: {err.percent:.2f} % error, IoU {err.iou:.3f}, {ex.n_wraps} wraps, "
              f"{len(ex.points)} points, {ex.wall_s:.1f} s -> {out}")
        if opts.get("grasp"):
            print(_grasp_line(grasp))
        if opts.get("rerun"):
            print(f"3D recording: {opts['rerun']} (open it with: rerun {opts['rerun']})")
    return 0


def _grasp_line(entry: dict) -> str:
    """One line of a ``grasp`` entry: held / planned per source."""
    from explore3d.app.grasp import SOURCES  # start-up: kept out of --help's

    parts = [f"{name} {entry[name]['held']}/{entry[name]['planned']}" if name in entry else f"{name} skipped"
             for name in SOURCES]
    return "grasps held: " + ", ".join(parts)


# --- other commands ------------------------------------------------------------------------------

def _foreign_recording(args):
    """The :class:`~explore3d.app.offline.Recording` of another controller's bag: the arm, band,
    rough bound and topics from the command line (``reconstruct --bag DIR --readings --arm ...``)."""
    import numpy as np  # start-up: kept out of explore3d --help's

    from explore3d.app.offline import Recording  # start-up: as above
    from explore3d.app.rosbag import BagTopics, read_joint_bag  # start-up: as above
    from explore3d.arm.urdf import load_arm  # start-up: as above
    from explore3d.feeling.detect import ContactBand  # start-up: as above
    from explore3d.strategy.explore import ExploreConfig  # start-up: as above

    spec = load_arm(args.arm)
    try:
        data = json.loads(Path(args.band).read_text(encoding="utf-8"))
        band = ContactBand.from_dict(data.get("contact_band", data))
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"--band {args.band}: not a contact band ({exc}); give a run's report.json or a JSON with "
                         "swept_rad and other_rad") from None
    if band.swept.shape != (spec.n_links,):
        raise ValueError(f"--band {args.band} has {band.swept.shape[0]} joints; the arm {spec.name!r} has {spec.n_links}")
    topics = BagTopics(joint_states=args.joint_states, references=args.references, base_pose=args.base_pose,
                       joint_names=tuple(args.joint_names.split(",")) if args.joint_names else None)
    logs = read_joint_bag(args.bag, spec, topics)
    return Recording(spec=spec, config=ExploreConfig(), band=band, centre=np.asarray(args.centre, float),
                     radius=float(args.radius), table_z=None, a=args.a, method=args.method, logs=logs)


def _reconstruct_log(args, out: Path, suffix: str) -> int:
    """``reconstruct --log DIR`` or ``--bag DIR``: the recorded run's estimate from its logs alone
    (:func:`explore3d.app.offline.reconstruct_recording`)."""
    foreign = args.arm is not None
    given = [flag for flag, v in (("POINTS", args.points), ("--free-space", args.free_space),
                                  ("--radius", None if foreign else args.radius)) if v is not None]
    if given or args.estimator != "inverse-hull" or (args.centre != "midrange" and not foreign):
        raise UsageError(f"--log and --bag rebuild the run as it was (its rough bound, free space and inverse hull): drop "
                         f"{', '.join(given) or '--centre/--estimator'}")
    if foreign:
        if args.bag is None or not args.readings:
            raise UsageError("--arm reads another controller's bag: give --bag DIR --readings (an explore3d recording "
                             "carries its arm)")
        if args.band is None or not isinstance(args.centre, tuple) or len(args.centre) != 3 or args.radius is None:
            raise UsageError("another controller's bag needs what the robot knew: --band FILE (the contact band, "
                             "e.g. a run's report.json), --centre X,Y,Z and --radius R (the rough bound, metres)")
    with quiet_c_output():
        from explore3d.app.export import write_mesh  # start-up: kept out of explore3d --help's
        from explore3d.app.offline import read_recording, reconstruct_recording  # start-up: as above
        from explore3d.app.pipeline import ReconstructionError  # start-up: as above
        from explore3d.robot.interface import LogMismatchError  # start-up: as above

        flag, source = ("--log", args.log) if args.log is not None else ("--bag", args.bag)
        try:
            if args.log is not None:
                rec = read_recording(args.log)
            elif foreign:
                rec = _foreign_recording(args)
            else:
                from explore3d.app.rosbag import read_bag  # start-up: kept out of explore3d --help's

                rec = read_bag(args.bag)
        except ValueError as exc:
            raise RunError(f"{flag}: {exc}") from None
        from explore3d.app.progress import Progress  # start-up: kept out of explore3d --help's

        try:
            with Progress(enabled=not args.quiet, prog=PROG) as progress:
                ex, est = reconstruct_recording(rec, replay=not args.readings, progress=progress)
                progress.finish()
        except ReconstructionError as exc:
            raise RunError(f"reconstruction failed: {exc}") from None
        except LogMismatchError as exc:
            raise RunError(f"{flag} {source} does not replay ({exc}): its logs were not recorded by this explore3d "
                           "with the recording's settings") from None
    if rec.config.mode == "planar":
        if suffix == "json":
            atomic_write_text(out, _dump([[float(x), float(y)] for x, y in list(est.exterior.coords)[:-1]]))
        else:  # extruded as run extrudes it: over the arm's sensed height band, or --height about its plane
            from explore3d.app.pipeline import extruded  # start-up: kept out of explore3d --help's

            write_mesh(extruded(est, ex, args.height), out, suffix)
        size = f"area {est.area:.6g} m^2"
    else:
        if suffix == "json":
            raise UsageError("the recording is of a 3D run: --out must be a mesh file (.obj .stl .ply .off .glb)")
        write_mesh(est, out, suffix)
        size = f"volume {est.volume:.6g} m^3"
    print(f"{ex.n_wraps} wraps replayed from {source}, {len(ex.points)} points, {size} -> {out}")
    return 0


def cmd_reconstruct(args) -> int:
    """The hull input is built as ``run`` builds it (:func:`explore3d.reconstruction.hull_input.hull_input_mask`:
    the rough bound, then the angular outlier filter over the wrap ids stored in points.ply)."""
    import numpy as np

    from explore3d.app.export import (  # start-up: kept out of explore3d --help's
        check_format,
        points_2d_if_planar,
        read_points_ply,
        write_mesh,
    )
    from explore3d.geometry.hull import resolve_centre
    from explore3d.reconstruction.hull_input import hull_input_mask, reconstruct_points

    out = Path(args.out)
    suffix = out.suffix.lower().lstrip(".")
    if suffix != "json":
        try:
            check_format(suffix)
        except ValueError as exc:
            raise UsageError(f"--out {out}: {exc} (or .json for a 2D polygon)") from None
    if args.log is not None and args.bag is not None:
        raise UsageError("--log and --bag are two forms of one recording: give one")
    if args.log is not None or args.bag is not None:
        return _reconstruct_log(args, out, suffix)
    if args.readings:
        raise UsageError("--readings reads a recording: give --log DIR or --bag DIR")
    if args.points is None:
        raise UsageError("reconstruct needs a point file (POINTS) or a run's recording (--log DIR or --bag DIR)")
    centre = args.centre
    if args.radius is not None and not isinstance(centre, tuple):
        raise UsageError("--radius needs an explicit --centre x,y[,z] (the rough centre it is measured from, metres)")
    pts3, props = read_points_ply(args.points, with_properties=True)
    pts = points_2d_if_planar(pts3)
    wrap = props.get("wrap", np.zeros(len(pts), dtype=np.int64))
    if isinstance(centre, tuple):
        if len(centre) == 3 and pts.shape[1] == 2:  # a run's rough centre (x, y, z) for its planar points
            centre = centre[:2]
        if len(centre) != pts.shape[1]:
            raise UsageError(f"--centre has {len(centre)} coordinates but the points are {pts.shape[1]}D")
    c = resolve_centre(pts, centre)
    radius = math.inf if args.radius is None else args.radius
    kept = int(hull_input_mask(pts, wrap, c, radius).sum())
    if kept <= pts.shape[1]:
        if args.radius is None:
            raise RunError(f"only {kept} of {len(pts)} points agree with the other wraps: too few for a "
                           f"{pts.shape[1]}D hull (at least {pts.shape[1] + 1} not in one "
                           f"{'line' if pts.shape[1] == 2 else 'plane'}); pass the points of a whole exploration")
        raise RunError(f"only {kept} of {len(pts)} points lie within --radius {args.radius:g} m of "
                       f"--centre {','.join(f'{x:g}' for x in c)} and agree with the other wraps; check both (see "
                       "report.json's config.centre_m and config.radius_m)")
    hull = reconstruct_points(pts, wrap, c, radius, a=args.a, method=args.method)
    if hull.dim == 2:
        poly = hull.polygon
        if suffix == "json":
            atomic_write_text(out, _dump([[float(x), float(y)] for x, y in list(poly.exterior.coords)[:-1]]))
        elif args.height is None:
            raise UsageError("the points are 2D (z = 0): write a polygon with --out X.json or give --height M to extrude")
        else:
            import trimesh  # start-up: kept out of explore3d --help's

            m = trimesh.creation.extrude_polygon(poly, float(args.height))
            m.apply_translation([0.0, 0.0, -0.5 * float(args.height)])  # centred on the points' plane z = 0
            write_mesh(m, out, suffix)
        print(f"polygon of {len(hull.vertices)} vertices, area {poly.area:.6g} m^2 -> {out}")
    else:
        if suffix == "json":
            raise UsageError("the points are 3D: --out must be a mesh file (.obj .stl .ply .off .glb)")
        m = hull.mesh
        swept = []
        if args.free_space is not None:
            from explore3d.reconstruction.freespace import load_swept  # start-up: kept out of explore3d --help's

            try:
                swept = load_swept(args.free_space)
            except ValueError as exc:
                raise RunError(f"--free-space: {exc}") from None
        if args.estimator == "inverse-hull" and swept:
            from explore3d.reconstruction.carve import carve  # start-up: kept out of explore3d --help's

            m = carve(m, swept).mesh
        elif args.estimator != "inverse-hull":
            from explore3d.reconstruction.estimators import estimate  # start-up: kept out of explore3d --help's

            normals = None
            if args.estimator == "implicit":
                if not {"nx", "ny", "nz"} <= props.keys():
                    raise UsageError(f"--estimator implicit needs the contacts' normals (nx, ny, nz) in {args.points}: "
                                     "use a points.ply of localised contacts (what 'run' writes by default)")
                normals = np.column_stack([props["nx"], props["ny"], props["nz"]])
            m = estimate(args.estimator, pts, wrap, c, radius, swept, a=args.a, normals=normals)
        write_mesh(m, out, suffix)
        print(f"mesh of {len(m.vertices)} vertices, {len(m.faces)} faces, volume {m.volume:.6g} m^3 -> {out}")
        import trimesh  # start-up: kept out of explore3d --help's

        if not trimesh.Trimesh(m.vertices, m.faces).is_watertight:  # what a loader's vertex merge gives
            print(f"warning: the estimate touches itself at a vertex or an edge (the carving or union left a pinch): "
                  f"{out} reloads with non-manifold edges",
                  file=sys.stderr)
    return 0


def _load_shape(spec: str, what: str):
    """A shapely Polygon from a JSON list of [x, y] (metres), else a closed mesh via load_object."""
    if spec.lower().endswith(".json"):
        from shapely.geometry import Polygon  # start-up: kept out of explore3d --help's

        p = Path(spec)
        if not p.is_file():
            raise RunError(f"{what} file not found: {p}; check the path")
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise RunError(f"cannot read {what} {p} as JSON ({exc}); give a list of [x, y] pairs in metres") from None
        try:
            poly = Polygon([(float(x), float(y)) for x, y in data])
        except (TypeError, ValueError) as exc:
            raise RunError(f"{what} {p} must be a JSON list of at least 3 [x, y] pairs ({exc})") from None
        if not poly.is_valid or poly.area <= 0:
            raise RunError(f"{what} {p} is not a valid polygon (self-intersecting or zero area)")
        return poly
    from explore3d.world.objects import load_object  # start-up: kept out of explore3d --help's

    _check_object_name(spec)
    return load_object(spec)


def cmd_evaluate(args) -> int:
    from explore3d.geometry.metrics import shape_error  # start-up: kept out of explore3d --help's

    est = _load_shape(args.estimate, "estimate")
    tru = _load_shape(args.truth, "truth")
    err = shape_error(est, tru)
    d = err.to_dict()
    if args.json:
        print(json.dumps(d, indent=2))
        return 0
    unit = "m^2" if err.dim == 2 else "m^3"
    print(f"percent error  {err.percent:.3f} %")
    print(f"IoU            {err.iou:.4f}")
    print(f"chamfer        {err.chamfer_m * 1e3:.3f} mm")
    print(f"hausdorff      {err.hausdorff_m * 1e3:.3f} mm")
    print(f"true size      {err.true_size:.6g} {unit}")
    print(f"estimate size  {err.estimate_size:.6g} {unit}")
    print(json.dumps(d))
    return 0


def cmd_compare(args) -> int:
    _check_object_name(args.object)
    opts = {k: getattr(args, k) for k in ("mode", "directions", "attempts", "angles", "jobs", "probes", "fingers",
                                          "pokes", "slides", "encircle")
            if getattr(args, k) is not None}
    config = explore_config({**opts, "probes": 0} if args.no_free_space else opts)
    if args.no_free_space:
        config = dataclasses.replace(config, free_space=False)
    with quiet_c_output():
        from explore3d.app.compare import compare, format_compare
        from explore3d.app.pipeline import NoContactError, ReconstructionError
        from explore3d.arm.urdf import load_arm  # start-up: kept out of explore3d --help's
        from explore3d.world.objects import load_object

        try:
            spec = load_arm(args.arm)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        mesh = load_object(args.object, size=args.size)
        from explore3d.app.progress import Progress  # start-up: kept out of explore3d --help's

        try:
            with Progress(enabled=not args.quiet, prog=PROG) as progress:
                report = compare(mesh, spec, config, a=args.a, progress=progress)
                progress.finish()
        except (NoContactError, ReconstructionError) as exc:
            raise RunError(str(exc)) from None
    report["object"] = args.object
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    print(f"{args.object}: {report['n_wraps']} wraps ({config.mode}), {report['n_contacts']} detections, "
          f"{report['localisation']['n_localised']} localised contacts ({report['localisation_used']['n_localised']} "
          f"hulled), {report['skin_contacts']} skin contacts ({report['skin_loaded']} carrying force)")
    print(format_compare(report))
    return 0


def cmd_sweep(args) -> int:
    """Parse -> :func:`explore3d.app.sweep.run_sweep` -> one summary line (stdout), and one line on
    stderr counting the failed combinations, if any.  Exit code 0 when at least one combination is
    stored as ok, 1 when every one failed (or the sweep could not start: folder busy, not a sweep's
    database, not writable), 2 for a usage error."""
    from explore3d.app.sweep import (  # start-up: kept out of explore3d --help's
        SweepBusyError,
        SweepDatabaseError,
        parse_grid,
        read_grid_file,
        run_sweep,
        sweep_tasks,
    )

    try:
        grid = read_grid_file(args.grid_file) if args.grid_file else {}
        grid.update(parse_grid(args.grid))
        sweep_tasks(args.objects, grid, size=args.size)  # every name, value and arm checked before any run
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    backend = "ray" if (args.ray or args.ray_address or os.environ.get("RAY_ADDRESS")) else "local"
    try:
        s = run_sweep(args.objects, args.out, grid, size=args.size, workers=args.workers,
                      jobs_per_run=args.jobs_per_run, backend=backend, ray_address=args.ray_address,
                      retry_failed=args.retry_failed, progress=not args.quiet)
    except (SweepBusyError, SweepDatabaseError) as exc:
        raise RunError(str(exc)) from None
    except OSError as exc:
        raise RunError(f"cannot write the sweep to {args.out} ({exc.strerror or exc}); choose a writable --out") from None
    if not args.quiet:
        lost = f", {s.lost} lost" if s.lost else ""
        print(f"sweep: {s.total} combinations, {s.stored_before} stored before, {s.ran} run ({s.ok} ok, "
              f"{s.failed} failed{lost}) on {backend} -> {Path(args.out) / 'sweep.db'}", flush=True)
    if s.not_ok_total:
        what = (f"{s.not_ok_total} of {s.total} combinations of the sweep are stored as failed or lost "
                f"(first: {s.first_failure}); see the reason column of 'explore3d sweep-report {args.out}'")
        if s.ok_total == 0:
            raise RunError(f"every run failed: {what}; fix the inputs, then run again with --retry-failed")
        print(f"{PROG}: warning: {' '.join(what.split())}", file=sys.stderr)
    return 0


def cmd_sweep_report(args) -> int:
    from explore3d.app.sweep_report import write_sweep_report  # start-up: kept out of explore3d --help's

    try:
        files = write_sweep_report(args.folder, args.out, thumbnails=args.thumbnails)
    except ValueError as exc:
        raise RunError(str(exc)) from None
    print(f"sweep report: {', '.join(p.name for p in files)} -> {files[0].parent}")
    return 0


def cmd_table1(args) -> int:
    try:
        from explore3d.app import table1  # start-up: kept out of explore3d --help's
    except ImportError as exc:
        raise RunError(f"explore3d.app.table1 is not available ({exc}); update explore3d") from None

    kw = {k: getattr(args, k) for k in ("a", "seed") if getattr(args, k) is not None}
    with quiet_c_output():  # PyBullet's banners would come before the table (or the JSON) on stdout
        rows = table1.table1_rows(**kw)
        rows3d = table1.table3d_rows(jobs=args.jobs) if args.three_d else None
    if args.json:
        print(_dump(rows if rows3d is None else {"table1": rows, "table3d": rows3d}), end="")
        return 0
    if hasattr(table1, "format_table"):
        print(table1.format_table(rows))
        if rows3d is not None:
            print()
            print(table1.format_table3d(rows3d))
        return 0
    print(f"{'case':<24} {'paper m^2':>12} {'paper %':>8} {'ours m^2':>12} {'ours %':>8}")
    for r in rows:
        def f(v, w, p):
            return f"{v:>{w}.{p}f}" if isinstance(v, (int, float)) and v is not None else f"{'-':>{w}}"
        print(f"{str(r.get('case')):<24} {f(r.get('paper_area_error_m2'), 12, 6)} {f(r.get('paper_percent'), 8, 2)} "
              f"{f(r.get('area_error_m2'), 12, 6)} {f(r.get('percent'), 8, 2)}")
    return 0


def arm_spec_from_args(args):
    """The :class:`ArmSpec` of ``explore3d arm``: ``--base`` with the given fields replaced."""
    from explore3d.arm.urdf import load_arm  # start-up: kept out of explore3d --help's

    try:
        base = load_arm(args.base)
        fields = {f.name for f in dataclasses.fields(base)}
        kw = {k: getattr(args, k) for k in fields if getattr(args, k, None) is not None}
        return dataclasses.replace(base, **kw)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def cmd_band(args) -> int:
    """``explore3d band``: the contact band as JSON (:meth:`ContactBand.to_dict`)."""
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise UsageError(f"--out {out}: the band is written as JSON; give a file name ending in .json")
    with quiet_c_output():
        from explore3d.arm.urdf import load_arm  # start-up: kept out of explore3d --help's

        try:
            spec = load_arm(args.arm)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        paths = []
        if args.log is not None:
            paths = sorted(Path(args.log).glob("*.npz")) if Path(args.log).is_dir() else []
            if not paths:
                raise RunError(f"--log {args.log} holds no .npz robot logs; give the folder of the arm's calibration logs")
        if not out.parent.is_dir():
            raise RunError(f"the folder of --out {str(out)!r} does not exist; create it first")
        if args.log is None:
            from explore3d.world.band import cached_band  # start-up: as above

            band = cached_band(spec, planar=args.planar)
            how = "measured on the simulated twin"
        else:
            from explore3d.robot.interface import RobotLog  # start-up: as above
            from explore3d.strategy.readings import band_from_readings  # start-up: as above

            try:
                band = band_from_readings([RobotLog.load(p) for p in paths], spec)
            except ValueError as exc:
                raise RunError(f"--log {args.log}: {exc}") from None
            how = f"from {len(paths)} calibration log(s)"
    atomic_write_text(out, _dump(band.to_dict()))
    print(f"contact band of {spec.name} ({spec.n_links} joints), {how} -> {out}")
    return 0


def cmd_arm(args) -> int:
    from explore3d.arm.urdf import write_arm_urdf  # start-up: kept out of explore3d --help's

    spec = arm_spec_from_args(args)
    path = write_arm_urdf(spec, args.out)
    print(f"arm {spec.name}: {spec.n_links} links of {spec.link_length} m (reach {spec.reach:.3f} m) -> {path}")
    return 0


def grasp_config(args):
    """The :class:`~explore3d.app.grasp.GraspConfig` of ``explore3d grasp``'s options."""
    from explore3d.app.grasp import GraspConfig  # start-up: kept out of --help's
    from explore3d.grasp.gripper import GripperSpec  # start-up: kept out of --help's
    from explore3d.world.grasping import ExecutionConfig  # start-up: kept out of --help's

    gripper = {k: v for k, v in (("friction", args.friction), ("grip_force_n", args.grip_force)) if v is not None}
    execution = {} if args.density is None else {"density": args.density}
    return GraspConfig(n=args.n, seed=args.seed, gripper=GripperSpec(**gripper),
                       execution=ExecutionConfig(**execution))


def cmd_grasp(args) -> int:
    with quiet_c_output():  # PyBullet's banners
        from explore3d.app.grasp import SOURCES, grasp_run  # start-up: kept out of --help's
        from explore3d.app.progress import Progress  # start-up: kept out of --help's

        with Progress(("writing",), unit="grasp", enabled=not args.quiet, prog=PROG) as progress:
            entry = grasp_run(args.run_dir, grasp_config(args), pictures=not args.no_pictures, progress=progress)
            progress.finish()
    for name in SOURCES:
        if name in entry:
            r = entry[name]
            rate = "-" if r["rate"] is None else f"{100 * r['rate']:.0f}%"
            lo, hi = r["wilson_95"]
            push = "" if r["push_median_m"] is None else f"  push {1e3 * r['push_median_m']:.1f} mm (median)"
            print(f"{name:12s} {r['held']:3d}/{r['planned']:<3d} held  {rate:>5s}  (95% {100 * lo:.0f}-{100 * hi:.0f}%)"
                  f"{push}")
        else:
            print(f"{name:12s} skipped: {entry['skipped'].get(name, '')}")
    print(f"-> {Path(args.run_dir) / 'report.json'} (grasp), grasps.json{'' if args.no_pictures else ', grasps.png'}")
    return 0


def cmd_objects(args) -> int:
    from explore3d.world.objects import BUILTIN_OBJECTS, object_size  # start-up: kept out of explore3d --help's

    rows = []
    for name, info in BUILTIN_OBJECTS.items():
        s = object_size(info.builder())
        rows.append({"name": name, "description": info.description, "extents_m": [float(x) for x in s["extents"]],
                     "volume_m3": s["volume"], "bounding_radius_m": s["bounding_radius"]})
    if args.json:
        print(_dump(rows), end="")
        return 0
    for r in rows:
        ext = " x ".join(f"{1e3 * x:.0f}" for x in r["extents_m"])
        print(f"{r['name']:<12} {ext:>16} mm  {r['volume_m3'] * 1e6:8.1f} cm^3  {r['description']}")
    return 0


# --- entry point ---------------------------------------------------------------------------------

def _setup_logging(verbose: int) -> None:
    """Log records of explore3d at WARNING (INFO with -v, DEBUG with -vv) to the terminal's stderr,
    also inside :func:`~explore3d.core.quiet.quiet_c_output` (whose block points fd 2 at /dev/null: the
    handler writes to whatever ``sys.stderr`` is at the time, which the block keeps on the terminal)."""
    level = logging.WARNING if not verbose else (logging.INFO if verbose == 1 else logging.DEBUG)
    logger = logging.getLogger("explore3d")
    logger.setLevel(level)
    if not any(getattr(h, "_explore3d_cli", False) for h in logger.handlers):
        handler = logging.StreamHandler(STDERR)
        handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
        handler._explore3d_cli = True
        logger.addHandler(handler)
        logger.propagate = False


def _say(msg: str) -> None:
    one_line = " ".join(str(msg).split())
    print(f"{PROG}: error: {one_line}", file=sys.stderr)


def _quiet_interrupt_unraisable(hook):
    """A ``sys.unraisablehook`` that drops the KeyboardInterrupt of a Ctrl-C that landed in a
    ``__del__`` or a callback (the run honours it at its next check), and once interrupted every
    such message (what the unwinding leaves half-made objects to say); the rest go to ``hook``."""
    def f(unraisable):
        if INTERRUPTED[0] or isinstance(unraisable.exc_value, KeyboardInterrupt):
            return
        hook(unraisable)
    return f


@contextlib.contextmanager
def _interrupt_handling():
    """For the length of ``main``: SIGINT raises KeyboardInterrupt once and is ignored afterwards
    (:func:`explore3d.core.interrupt.sigint_handler`), and an interrupt swallowed in a ``__del__`` prints
    nothing.  Only in the main thread; the previous handler and hook are restored, and the flag is
    cleared (library calls after ``main`` in the same process are not taken for interrupted); the
    yielded dict's ``"interrupted"`` says whether a SIGINT came."""
    INTERRUPTED[0] = False
    state = {"interrupted": False}
    old_hook = sys.unraisablehook
    sys.unraisablehook = _quiet_interrupt_unraisable(old_hook)
    old = None
    if threading.current_thread() is threading.main_thread():
        old = signal.signal(signal.SIGINT, sigint_handler)
    try:
        yield state
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
        sys.unraisablehook = old_hook
        state["interrupted"], INTERRUPTED[0] = INTERRUPTED[0], False


def main(argv=None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); returns the exit code.  Ctrl-C
    (SIGINT) at any moment: exit 130 and the one line ``explore3d: error: interrupted``."""
    state = {"interrupted": False}
    try:
        with _interrupt_handling() as state:
            code = _main(argv)
    except KeyboardInterrupt:  # arrived between the handler's installation and _main's own handling
        code = None
    if code is None or (state["interrupted"] and code != 130):  # also an interrupt some code swallowed
        _say("interrupted")
        code = 130
    return code


def _main(argv) -> int:
    parser = build_parser()
    try:
        try:
            args = parser.parse_args(argv)
            _setup_logging(args.verbose)
            return int(args.func(args) or 0)
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception:
            if INTERRUPTED[0]:  # what an interrupt left behind (a library that swallowed it, a half import)
                raise KeyboardInterrupt from None
            raise
    except SystemExit as exc:  # --help, --version
        return exc.code if isinstance(exc.code, int) else 0
    except UsageError as exc:
        _say(exc)
        return 2
    except RunError as exc:
        _say(exc)
        return 1
    except KeyboardInterrupt:
        _say("interrupted")
        return 130
    except (ValueError, OSError) as exc:  # MeshError, NotAVolumeError, file errors
        msg = str(exc) or type(exc).__name__
        if isinstance(exc, OSError) and exc.filename is not None:
            msg = f"{exc.strerror or exc} : {exc.filename}; check the path and permissions"
        _say(msg)
        log.debug("the error in full", exc_info=True)
        return 1
    except Exception as exc:  # noqa: BLE001 - the library's and its dependencies' other errors: one line each
        _say(library_error_message(exc))
        log.debug("the error in full", exc_info=True)
        return 1


def library_error_message(exc: BaseException) -> str:
    """One line for an error of the library or a dependency that no command turned into a usage or
    run error: what failed (by the error's origin) and what to try."""
    kind, module = type(exc).__name__, type(exc).__module__ or ""
    text = " ".join(str(exc).split()) or kind
    if isinstance(exc, MemoryError):
        return ("out of memory; use a smaller object or rough bound (--size, --radius), fewer wraps "
                "(--directions/--attempts) or fewer --jobs")
    if module.startswith("pybullet"):
        return (f"the simulator failed ({text}); check the object mesh (closed, at most "
                "explore3d.app.pipeline.MAX_OBJECT_FACES faces, in metres) and the arm's URDF")
    if module.startswith("sqlite3"):
        return f"database error ({kind}: {text}); move the sweep folder's sweep.db away or choose another --out"
    if isinstance(exc, (FloatingPointError, ArithmeticError)):
        return f"numerical failure ({kind}: {text}); check the inputs' sizes and --a"
    return f"unexpected {kind}: {text}; run again with -vv for the details and report it"
