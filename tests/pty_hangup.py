"""Hanging up the master end of a fake printer's pty while its own threads may still hold the number."""

from __future__ import annotations

import os


def hang_up(master: int) -> None:
    """End the pty behind descriptor `master` for the host (its port reads EOF or EIO: the printer is gone)
    while the number stays taken, now /dev/null, until the fake printer closes it after joining its threads.

    Why not os.close: the fake printer's reader thread may be about to select() or read() that number, and
    a number freed here is the one the code under test's next open() gets (a G-code file, say); the reader
    then swallows that file's first 4 KiB from under it (seen: a resume check read 144 lines short)."""
    null = os.open(os.devnull, os.O_RDWR)
    try:
        os.dup2(null, master)  # closes the pty's master file and takes its number in one step
    finally:
        os.close(null)
