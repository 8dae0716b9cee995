"""The fake printers' hang-up (tests/pty_hangup.py): the host sees the printer gone, and the master's number
is never handed to the next open() while the fake printer's threads may still read it."""

from __future__ import annotations

import errno
import os

from pty_hangup import hang_up


def test_hang_up_ends_the_link_but_keeps_the_number(tmp_path):
    master, slave = os.openpty()
    try:
        os.write(master, b"ok\n")
        assert os.read(slave, 16) == b"ok\n"
        hang_up(master)
        # the host's end reads the hang-up (Linux: EIO once the master is gone)
        try:
            got = os.read(slave, 16)
        except OSError as exc:
            assert exc.errno == errno.EIO
        else:
            assert got == b""
        # a stale read of the number by a fake printer's thread reads nothing and steals nothing
        assert os.read(master, 4096) == b""
        path = tmp_path / "part.gcode"
        path.write_bytes(b"G1 X1\n" * 2000)
        with open(path, "rb") as f:
            assert f.fileno() != master  # the number is not free for the next open()
            assert os.read(master, 4096) == b""
            assert f.read() == b"G1 X1\n" * 2000
    finally:
        os.close(master)
        os.close(slave)
