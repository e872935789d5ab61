"""Emulated devices speaking the real protocols over ptys and loopback TCP."""
