"""`gonio bench`: list the performance and accuracy scripts in bench/, run one, some or all of
them and, with --doc, write their latest output into the generated blocks of
docs/performance.md (or another file)."""

from __future__ import annotations

import argparse
import ast
import re
import subprocess
import sys
from pathlib import Path

from gonio.errors import GonioError

BENCH_DIR = Path(__file__).resolve().parents[2] / "bench"
BEGIN, END = "<!-- bench:{name}:begin -->", "<!-- bench:{name}:end -->"
DEFAULT_DOC = BENCH_DIR.parent / "docs" / "performance.md"
ALL = "all"


def register(sub: argparse._SubParsersAction) -> None:
    """Add the `bench` verb."""
    p = sub.add_parser("bench", help="run the scripts in bench/ (speed, error vs run time)",
                       description=__doc__)
    p.add_argument("names", nargs="*", metavar="NAME",
                   help=f"scripts to run, e.g. bsdf_throughput, or {ALL!r} for every one "
                        "(none: list them, one line each)")
    p.add_argument("--doc", type=Path, nargs="?", const=DEFAULT_DOC, metavar="FILE",
                   help="write each output between its markers in FILE (default: "
                        "docs/performance.md)")
    p.set_defaults(func=run)


def available() -> dict[str, Path]:
    """Benchmark scripts of this checkout, by name."""
    if not BENCH_DIR.is_dir():
        raise GonioError(f"no bench/ folder beside the package ({BENCH_DIR}); run from a checkout")
    return {p.stem: p for p in sorted(BENCH_DIR.glob("*.py")) if not p.stem.startswith("_")}


def summary(script: Path) -> str:
    """The first line of a script's docstring: what it measures, in one line."""
    doc = ast.get_docstring(ast.parse(script.read_text(), filename=str(script))) or ""
    return doc.strip().splitlines()[0] if doc.strip() else "(no description)"


def listing(scripts: dict[str, Path]) -> str:
    """One line per script: its name and what it measures."""
    width = max(map(len, scripts), default=0)
    return "\n".join(f"{name:<{width}}  {summary(path)}" for name, path in scripts.items())


def check_markers(doc: Path, names: list[str]) -> None:
    """Raise a GonioError naming the first script whose begin/end markers the file lacks."""
    text = doc.read_text()
    for name in names:
        begin, end = BEGIN.format(name=name), END.format(name=name)
        if begin not in text or end not in text:
            raise GonioError(f"{doc}: no '{begin}' ... '{end}' markers for bench script {name}")


def update_doc(doc: Path, name: str, output: str) -> None:
    """Replace the text between the script's begin/end markers with its output."""
    check_markers(doc, [name])
    text = doc.read_text()
    begin, end = BEGIN.format(name=name), END.format(name=name)
    block = f"{begin}\n```\n{output.rstrip()}\n```\n{end}"
    pattern = re.escape(begin) + ".*?" + re.escape(end)
    doc.write_text(re.sub(pattern, lambda _: block, text, flags=re.S))


def run(args: argparse.Namespace) -> int:
    """With no name, list the scripts; else run the chosen ones (all: every one) one after
    another, echoing their output."""
    scripts = available()
    if args.doc and not args.doc.is_file():
        hint = (f" (`gonio bench {args.doc} --doc` writes into {DEFAULT_DOC.name}: the names "
                "go before a bare --doc)" if str(args.doc) in (*scripts, ALL) else "")
        raise GonioError(f"--doc {args.doc}: no such file{hint}")
    if not args.names:
        print(listing(scripts))
        return 0
    names = list(scripts) if args.names == [ALL] else args.names
    unknown = sorted(set(names) - set(scripts))
    if unknown:
        raise GonioError(f"unknown bench script(s) {', '.join(unknown)}; `gonio bench` lists "
                         f"them, `gonio bench {ALL}` runs every one")
    if args.doc:
        check_markers(args.doc, names)  # before any script runs (some take minutes)
    status = 0
    for name in names:
        print(f"== {name}", flush=True)
        done = subprocess.run([sys.executable, str(scripts[name])], capture_output=True, text=True)
        print(done.stdout, end="")
        if done.returncode != 0:
            print(done.stderr, end="", file=sys.stderr)
            status = 1
        elif args.doc:
            update_doc(args.doc, name, done.stdout)
    return status
