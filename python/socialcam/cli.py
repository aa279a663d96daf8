"""Command line: ``socialcam demo``, ``socialcam render``, ``socialcam poses``."""

from __future__ import annotations

import argparse
import json
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
    pz = sub.add_parser(
        "poses",
        help="camera poses of social-camera videos on one clock (poses.csv, sync.json, "
        "report.json)",
    )
    pz.add_argument("videos", nargs="+", metavar="VIDEO", help="one video per wearer")
    pz.add_argument("--out", required=True, help="output folder")
    pz.add_argument(
        "--fps", type=float, default=10.0, help="output rate, Hz (default: %(default)s)"
    )
    pz.add_argument(
        "--keyframe-fps",
        type=float,
        default=1.0,
        help="least keyframe rate, Hz; head turns add keyframes (default: %(default)s)",
    )
    pz.add_argument(
        "--camera-model",
        default="SIMPLE_RADIAL",
        help="COLMAP lens model per wearer, e.g. SIMPLE_RADIAL, RADIAL, OPENCV_FISHEYE "
        "(default: %(default)s)",
    )
    pz.add_argument(
        "--offset",
        action="append",
        default=[],
        metavar="PERSON=SECONDS",
        help="manual clock offset of a video (repeatable); needed for videos without audio",
    )
    pz.add_argument(
        "--eye-height", type=float, default=None, help="mean camera height above the floor, m"
    )
    pz.add_argument(
        "--known-distance",
        nargs=5,
        default=None,
        metavar=("PERSON_A", "TIME_A", "PERSON_B", "TIME_B", "METRES"),
        help="distance between two camera centres (persons at common-clock times)",
    )
    pz.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    pz.add_argument("--json", action="store_true", help="print the whole report as JSON")
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
        report = run_demo(
            args.out, seed=args.seed, plots=not args.no_plots, progress=sys.stderr.isatty()
        )
        print(json.dumps(report, indent=2, default=float) if args.json else _summary(report))
        print(f"report written to {args.out}/report.json")
    return 0


def _poses(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    from socialcam.pipeline import poses

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
    try:
        rec = poses(
            args.videos,
            args.out,
            fps=args.fps,
            sync=offsets or None,
            known_distance=known,
            eye_height=args.eye_height,
            keyframe_fps=args.keyframe_fps,
            camera_model=args.camera_model,
            seed=args.seed,
            progress=sys.stderr.isatty(),
        )
    except ValueError as exc:
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


if __name__ == "__main__":
    raise SystemExit(main())
