"""The `gonio` command line, the composition root above `gonio` and `calibration`: it wires
the instrument engine, the run store and the reduction into one verb per module of
`gonio_cli.commands` (`gonio_cli.main`)."""
