"""The first hour: the welcome view and lost hint, the calibration wizard, Help, and the pieces that put them
into the main window (`pieces`; docs/gui-first-hour.md)."""
