"""CLI verbs, one module each; gonio.cli discovers them from COMMANDS."""
