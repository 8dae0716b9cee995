"""Scan to print: reconstruct an object standing on the marker board (see docs/scanning.md)."""
