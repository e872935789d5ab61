"""CLI verbs, one module each; gonio_cli.main discovers them from COMMANDS."""
