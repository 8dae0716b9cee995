"""Subcommands of the `arapp` CLI, one module each (see arapp.cli).

Each module's `run` imports what it needs inside the function on purpose:
`arapp --help` and every other command load only their own dependencies
(OpenCV, Qt, GL, trimesh, the slicer), which keeps start-up fast.
"""
