"""`gonio emulate CFG`: serve a config's devices on ptys and loopback sockets until interrupted,
printing one line per device, `NAME PROTOCOL ENDPOINT`, once every emulator is ready to answer
(the emulated bench has computed what the stages' first reading needs). `--bind HOST` makes
the emulators that listen on TCP (Modbus TCP, and a line device given a TCPIP SOCKET
resource) listen on HOST instead of 127.0.0.1, with a warning: they are then open to whoever
can reach that address."""

from __future__ import annotations

import argparse
import ipaddress
import signal
import socket
import sys
import threading

from gonio.errors import ConfigError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `emulate` verb."""
    p = subparsers.add_parser("emulate", help="serve the emulated devices of a config",
                              description=__doc__)
    p.add_argument("config", help="instrument config TOML file")
    p.add_argument("--time-scale", type=float, metavar="X",
                   help="virtual seconds per real second (inf = instant moves), instead of "
                        "the config's [sim] time_scale")
    p.add_argument("--bind", metavar="HOST", default="127.0.0.1",
                   help="address the TCP emulators listen on, Modbus TCP and TCPIP SOCKET "
                        "(default 127.0.0.1: this machine only; another opens the devices to "
                        "the network)")
    p.set_defaults(func=run)


def is_loopback(host: str) -> bool:
    """True if HOST can be bound and every address it names is this machine's loopback;
    ConfigError (one line) if it cannot be listened on."""
    try:
        found = socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM)
        family, _, _, _, address = found[0]
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.bind(address)
    except OSError as exc:
        raise ConfigError(f"--bind {host}: cannot listen there ({exc.strerror or exc})") from None
    return all(ipaddress.ip_address(info[4][0]).is_loopback for info in found)


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT or SIGTERM."""
    from gonio.config import load_config
    from gonio.simulate import serve

    cfg = load_config(args.config)
    if not is_loopback(args.bind):
        tcp = [name for name, dev in cfg.devices.items() if dev.networked]
        if not tcp:
            raise ConfigError(f"--bind {args.bind}: {args.config} has no Modbus TCP device "
                              "(serial and RTU devices are ptys, local only)")
        print(f"gonio emulate: warning: --bind {args.bind}: {', '.join(tcp)} listen beyond "
              "this machine: anyone who can reach it can move the stages and read the "
              "detector", file=sys.stderr, flush=True)
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    with serve(cfg, args.time_scale, args.bind) as bench:
        for endpoint in bench.endpoints.values():
            print(endpoint.line, flush=True)
        done.wait()
    return 0
