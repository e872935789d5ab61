"""`gonio devices CONFIG`: open every device of an instrument config and print one line per
device (its identity as it reported it), one per axis (its position in degrees) and the
detector's reading, and a line when the detector's sensor head cannot take the config's
wavelength; nothing moves and none of the config's settings is sent. `--sim [NAMES]` asks the
emulated devices instead, as `gonio scan --sim` does.

exit status: 0 every device answered, 1 some did not (its line says why; the others are
still asked) or cannot measure as configured (its head's range leaves out the wavelength),
2 bad input (a config that does not load, a bad option).

`gonio devices --list`: the serial ports and VISA resources of this machine, each as a
`port = "..."` or `resource = "..."` line to paste into a config.
"""

from __future__ import annotations

import argparse
import sys

from gonio.errors import GonioError
from gonio_cli.commands.scan import add_sim_option, plan_given_to_sim


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `devices` verb."""
    p = subparsers.add_parser("devices", help="identify every device, read positions; "
                              "move nothing", description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("config", nargs="?", help="instrument config TOML file")
    p.add_argument("--list", action="store_true",
                   help="list this machine's serial ports and VISA resources instead")
    add_sim_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The listing, or the check of CONFIG's devices (the exit status of the module doc)."""
    if args.config is None:
        args.config, args.sim = plan_given_to_sim(args.sim)
    if args.list:
        if args.config or args.sim:
            raise GonioError("--list takes no CONFIG and no --sim")
        from gonio.port_inventory import inventory_lines

        print("\n".join(inventory_lines()))
        return 0
    if not args.config:
        raise GonioError("a CONFIG file is needed (or --list)")
    return _check(args.config, args.sim)


def _check(path: str, sim: list[str] | bool | None) -> int:
    """Check the config's devices (the emulated ones under --sim) and print the report."""
    from gonio.config import load_config
    from gonio.connection_check import check_connections

    cfg = load_config(path)
    if sim is None:
        report = check_connections(cfg)
    else:
        from gonio.simulate import simulation

        with simulation(cfg, None if sim is True else sim) as emulated:
            report = check_connections(emulated.config, emulated.positions.update)
    print("\n".join(report.lines()), flush=True)
    if report.silent:
        print(f"gonio devices: {len(report.silent)} of {len(cfg.devices)} devices did not "
              f"answer: {', '.join(report.silent)}", file=sys.stderr)
    if report.unfit:
        print(f"gonio devices: cannot measure as configured: {', '.join(report.unfit)}",
              file=sys.stderr)
    return 1 if report.silent or report.unfit else 0
