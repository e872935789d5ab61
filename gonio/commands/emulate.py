"""`gonio emulate CFG`: serve a config's devices on ptys and loopback sockets until interrupted,
printing one line per device, `NAME PROTOCOL ENDPOINT`."""

from __future__ import annotations

import argparse
import signal
import threading


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `emulate` verb."""
    p = subparsers.add_parser("emulate", help="serve the emulated devices of a config",
                              description=__doc__)
    p.add_argument("config", help="instrument config TOML file")
    p.add_argument("--time-scale", type=float, metavar="X",
                   help="virtual seconds per real second (inf = instant moves), instead of "
                        "the config's [sim] time_scale")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT or SIGTERM."""
    from gonio.config import load_config
    from gonio.simulate import serve

    cfg = load_config(args.config)
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    with serve(cfg, args.time_scale) as bench:
        for endpoint in bench.endpoints.values():
            print(endpoint.line, flush=True)
        done.wait()
    return 0
