"""Printing in the window: the print dialog and panel, Printer set-up, the bed anchor, the temperature graph."""
