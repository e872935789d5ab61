"""gonio: the instrument — configs, plans, scan engine, run store and geometry (its command
line is gonio_cli)."""
