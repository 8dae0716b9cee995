"""Subcommands of the `arapp` CLI, one module each (see arapp.cli)."""
