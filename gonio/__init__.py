"""gonio: the instrument — configs, plans, scan engine, run store, geometry and CLI."""
