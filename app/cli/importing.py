"""`imucap import`: another system's logged session -> an imucap session recording.

    imucap import FOLDER_OR_FILES... --out SESSION.h5 [--format auto|ximu3|mtmanager|dot|mvnx] [--truth T.npz]
                  [--calibration standing|walk|auto] [--map ID=SITE ...] [--height M] [--no-reconstruct] [--json]
    imucap import WALK_FILES... --calibration-trial NPOSE_FILES... [LEG_CYCLE_FILES...] --out S.h5 [--json]
    imucap import SESSION_DIR --out-dir DIR [--calibration-trial ...] [--json]

Why: a researcher's sessions are often logged with the sensor maker's own software. Once
imported, ``imucap replay`` reconstructs them with any model, sensor subset or step list,
and ``imucap export`` writes BVH, OpenSim, HDF5 or CSV, exactly as for a session recorded
here. The import keeps the raw stream (on the 60 Hz grid the live hub uses, by the live
app's slerp resampler), adds one calibration computed from the standing start (the log
has no table or T-pose window), and reconstructs the body with the default model and
every imported sensor (``--no-reconstruct`` skips that), so ``imucap export`` works at once.

Calibration (``calibration.imported``): the stand fixes each sensor's tilt and
sensor-to-bone; the subject's forward comes from the knees. ``--calibration walk`` also
gives each sensor its own heading from the gait (the swing axis of thighs and shanks,
every sensor's path between two still moments: ``calibration.gait_heading``, as the live
walk protocol), for sensors whose frames do not share one heading; ``standing`` assumes
they do; ``auto`` (default) is ``walk`` when the log holds walking. ``--json`` lists under
``calibration.warnings`` each sensor whose heading is off the others' or that keeps the
shared one, a line starting with its site; they are printed on stderr too.

A session of trials (``app.importing.trials``, ``calibration.trials``): a walk trial with no
still start takes each sensor's tilt and mounting from ``--calibration-trial`` (an N-pose
trial; leg-cycle trials give the thighs' and shanks' flexion axes), sensors matched by id
(DOT address, MT Manager device id), and each sensor's heading from the walk itself;
``--json``'s ``calibration.sensors`` says which trial calibrated each sensor. ``--out-dir``
imports a session folder, one folder per trial: trials named npose/static/stand are
standing calibration trials, leg/swing/cycle leg-cycle trials, every other one a walk.

A messy folder imports: sensors without a site are skipped with a warning (``warnings``),
files that are not exports are listed as ignored, a byte-identical copy of an export is
skipped with a warning; a file that claims to be an export but is damaged stops the
import with its one-line reason. ``log_time_origin_s`` is the original log's time of the
recording's frame 0 (kept in the recording and in every export; a BVH's goes beside it
in ``NAME.bvh.json``).

Formats (``--format auto``, the default, tells them apart):
- ``ximu3``: the x-IMU3 GUI's data logs (``drivers.ximu3``): one folder holding a folder
  per device.
- ``mtmanager``: MT Manager text/CSV exports (MTi, MTw Awinda), one file per sensor;
- ``dot``: Xsens DOT app CSV exports, one file per sensor (``drivers.xsens_export``).
  Give the folder holding them (its .txt/.csv files that are exports are read, others
  are listed as ignored) or the files themselves.
- ``mvnx``: an Xsens MVN take exported as MVNX (``drivers.xsens_export.mvnx``), one file
  for the whole suit. Its sensors map to sites by their MVN labels (``RightLowerLeg`` ->
  r_shank, ``T8`` -> torso, ``RightForeArm`` -> r_wrist); the hands and shoulders have
  no site and are listed as not used. MVNX holds no sensor rate, so the calibration
  takes it from orientation; the subject's height is MVN's body's unless ``--height`` says
  otherwise. ``--truth TRUTH.npz`` also writes MVN's own solution of the
  take (all 23 segments), so ``imucap replay SESSION.h5 --sensors ... --truth TRUTH.npz``
  scores a re-run with a few of the suit's sensors against the whole suit's answer.

Sensors map to sites by ``--map ID=SITE``, where ID is any name the sensor goes by: its
device name or tag (x-IMU3 device name, DOT tag), its id (x-IMU3 serial, MT Manager
Device ID, DOT address) or its file's stem. Without a map, a name that says a segment
maps by itself: site names, the names suits use ("Left Lower Leg" -> l_shank, see
``DEVICE_SITES``) and OpenSense-style bone names ("LFemur", "tibia_r_imu", see ``BONES``).

An export without Gyr_* columns (the DOT app's default Quat + FreeAcc) is recorded
without gyro, as it was logged; the standing calibration, which needs a rate to find
the still start, gets one from the orientation (``gyro_from_orientation``).

Sensors whose clocks are not one (a DOT set that was not synchronised) are aligned at
their first samples, which is only as good as their simultaneous start; the summary says
which was done (``clock``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from app.importing import (
    BONES,
    DEVICE_SITES,
    FORMATS,
    SOURCE_TITLES,
    Imported,
    Source,
    gyro_from_orientation,
    import_mvnx,
    import_paths,
    import_sources,
    import_ximu3,
    import_xsens,
    site_for,
)
from app.importing.trials import import_session, import_with_calibration
from calibration.imported import MODES as CALIBRATIONS
from inference.body.skeleton import parse_sites


def _mapping(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--map {item!r}: expected ID=SITE")
        name, site = item.rsplit("=", 1)
        out[name.strip()] = parse_sites([site.strip()])[0]
    return out


def _summary(res: Imported) -> dict:
    return {"recording": str(res.path), "format": res.format, "sites": list(res.sites), "frames": res.frames,
            "duration_s": res.duration_s, "still_start_s": res.still_s, "forward_G": res.forward_G,
            "forward_from": res.forward_from, "clock": res.clock, "log_time_origin_s": round(res.grid_t0, 6),
            "calibration": res.calibration, "reconstruction": res.reconstruction, "warnings": res.warnings,
            "devices": res.devices, "ignored": res.ignored, **({"truth": res.truth} if res.truth else {})}


def _warn(res: Imported) -> None:
    for w in res.warnings + res.calibration.get("warnings", []) + res.calibration.get("notes", []):
        print(f"imucap import: warning: {w}", file=sys.stderr)


def _run_session(args: argparse.Namespace) -> int:
    if len(args.logs) != 1 or not args.logs[0].is_dir():
        raise ValueError("--out-dir imports a session folder (one folder per trial); give just that folder")
    cal, done = import_session(args.logs[0], args.out_dir, args.calibration_trial or (), args.format,
                               _mapping(args.map), args.height, args.reconstruct)
    for _, res in done:
        _warn(res)
    if args.json:
        print(json.dumps({"session": str(args.logs[0]), "calibration_trials": [p.name for p in cal],
                          "trials": {name: _summary(res) for name, res in done}}))
    else:
        for name, res in done:
            print(f"{name}: {len(res.sites)} sensors, {res.duration_s} s, calibrated from "
                  f"{', '.join(res.calibration.get('trials', []))} -> {res.path}")
    sys.stdout.flush()
    return 0


def run_import(args: argparse.Namespace) -> int:
    if (args.out is None) == (args.out_dir is None):
        raise ValueError("give --out S.h5 (one log or trial) or --out-dir DIR (a session folder of trials)")
    if args.out_dir is not None:
        return _run_session(args)
    if args.calibration_trial:
        if args.truth is not None:
            raise ValueError("--truth: only an MVN take (.mvnx) holds a full-body solution to score against")
        res = import_with_calibration(args.logs, args.calibration_trial, args.out, args.format, _mapping(args.map),
                                      args.height, args.reconstruct)
    else:
        res = import_paths(args.logs, args.out, args.format, _mapping(args.map), args.height, args.truth,
                           args.calibration, args.reconstruct)
    _warn(res)
    if args.json:
        print(json.dumps(_summary(res)))
    else:
        how = (f"from {', '.join(res.calibration['trials'])}" if res.calibration.get("trials")
               else f"on the {res.still_s} s still stand")
        print(f"imported {len(res.sites)} sensors ({', '.join(res.sites)}) from an {SOURCE_TITLES[res.format]}, "
              f"{res.duration_s} s, calibrated ({res.calibration.get('method')}) {how} -> {res.path}")
        if res.ignored:
            what = "not used" if res.format == "mvnx" else "ignored (not Xsens exports)"
            print(f"{what}: {', '.join(res.ignored)}")
    sys.stdout.flush()
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("import", help="turn another system's logged session into a session recording",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("logs", type=Path, nargs="+", metavar="FOLDER_OR_FILES",
                   help="an x-IMU3 log folder, Xsens export folders/files (one file per sensor), or an MVN "
                        "take's .mvnx file")
    p.add_argument("--out", type=Path, default=None, help="the session recording to write (.h5)")
    p.add_argument("--out-dir", type=Path, default=None, metavar="DIR",
                   help="import a session folder (one folder per trial): every walk trial to DIR/<trial>.h5, "
                        "calibrated from the session's calibration trials")
    p.add_argument("--calibration-trial", type=Path, nargs="+", default=None, metavar="FILES",
                   help="calibrate from another trial of the same session (its folder or files; several trials: "
                        "an N-pose, leg cycles), matching sensors by id")
    p.add_argument("--format", default="auto", choices=FORMATS, help="the log's format (default: told from the files)")
    p.add_argument("--map", action="append", default=[], metavar="ID=SITE",
                   help="sensor name, id or file stem -> site, where the name does not say it (repeatable)")
    p.add_argument("--height", type=float, default=None, help="the subject's height in m (stored for replay)")
    p.add_argument("--truth", type=Path, default=None, metavar="TRUTH.npz",
                   help="with an MVN take: also write MVN's own full-suit solution, for imucap replay --truth")
    p.add_argument("--calibration", default="auto", choices=CALIBRATIONS,
                   help="standing: one heading for all sensors; walk: each sensor's heading from the gait; auto "
                        "(default): walk when the log holds walking")
    p.add_argument("--no-reconstruct", dest="reconstruct", action="store_false",
                   help="only calibrate; by default the import also reconstructs the body with the default model "
                        "and every imported sensor, so imucap export works on it at once")
    p.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    p.set_defaults(func=run_import)


__all__ = ["BONES", "DEVICE_SITES", "FORMATS", "Imported", "Source", "gyro_from_orientation", "import_mvnx",
           "import_paths", "import_sources", "import_xsens", "import_ximu3", "register", "site_for"]
