"""`gonio bench`: run the performance and accuracy scripts in bench/ and, with --readme,
write their latest output into the README's performance section."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

from gonio.errors import GonioError

BENCH_DIR = Path(__file__).resolve().parents[2] / "bench"
BEGIN, END = "<!-- bench:{name}:begin -->", "<!-- bench:{name}:end -->"


def register(sub: argparse._SubParsersAction) -> None:
    """Add the `bench` verb."""
    p = sub.add_parser("bench", help="run the scripts in bench/ (speed, error vs run time)")
    p.add_argument("names", nargs="*", help="scripts to run, e.g. bsdf_throughput (default: all)")
    p.add_argument("--list", action="store_true", help="list the scripts and exit")
    p.add_argument("--readme", type=Path, help="write each output into this README's section")
    p.set_defaults(func=run)


def available() -> dict[str, Path]:
    """Benchmark scripts of this checkout, by name."""
    if not BENCH_DIR.is_dir():
        raise GonioError(f"no bench/ folder beside the package ({BENCH_DIR}); run from a checkout")
    return {p.stem: p for p in sorted(BENCH_DIR.glob("*.py")) if not p.stem.startswith("_")}


def update_readme(readme: Path, name: str, output: str) -> None:
    """Replace the text between the script's begin/end markers with its output."""
    text = readme.read_text()
    begin, end = BEGIN.format(name=name), END.format(name=name)
    if begin not in text or end not in text:
        raise GonioError(f"{readme}: no '{begin}' ... '{end}' markers for bench script {name}")
    block = f"{begin}\n```\n{output.rstrip()}\n```\n{end}"
    pattern = re.escape(begin) + ".*?" + re.escape(end)
    readme.write_text(re.sub(pattern, lambda _: block, text, flags=re.S))


def run(args: argparse.Namespace) -> int:
    """Run the chosen scripts one after another, echoing their output."""
    scripts = available()
    if args.list:
        print("\n".join(scripts))
        return 0
    unknown = sorted(set(args.names) - set(scripts))
    if unknown:
        raise GonioError(f"unknown bench script(s) {', '.join(unknown)}; see gonio bench --list")
    status = 0
    for name in args.names or list(scripts):
        print(f"== {name}", flush=True)
        done = subprocess.run([sys.executable, str(scripts[name])], capture_output=True, text=True)
        print(done.stdout, end="")
        if done.returncode != 0:
            print(done.stderr, end="", file=sys.stderr)
            status = 1
        elif args.readme:
            update_readme(args.readme, name, done.stdout)
    return status
