"""Command line: ``socialcam demo``."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

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
    args = parser.parse_args(argv)
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


if __name__ == "__main__":
    raise SystemExit(main())
