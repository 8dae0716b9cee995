"""Guard against PySide6 6.12.0's reference-count bug on None/True/False under Python 3.11.

What goes wrong: with PySide6(-Essentials) 6.12.0 on CPython 3.11, every
call of a Qt method that returns void (`label.setText`, `widget.update`,
`processEvents`, ...) drops one reference to `None` that it never took, and
every `Signal.emit()` drops one to `True`. The desktop app makes hundreds of
such calls a second; once `None`'s (or `True`'s) count reaches zero CPython
aborts with "Fatal Python error: none_dealloc" (measured: a replay aborts
within seconds to minutes). PySide6 6.11.3 has no such leak, and Python 3.12+
makes these singletons immortal, where the bug is harmless.

The guard does what Python 3.12 does: it gives the three singletons a
reference count no program can exhaust. They are statically allocated and
never freed, so a larger count changes nothing else. It acts only on
CPython < 3.12.
"""

from __future__ import annotations

import ctypes
import sys

HEADROOM = 1 << 40  # references added: ~10^12 leaked decrefs before any risk
_applied = False


def immortalize_singletons() -> bool:
    """Raise the reference counts of None, True and False by HEADROOM (once per process); True if applied."""
    global _applied
    if _applied or sys.implementation.name != "cpython" or sys.version_info >= (3, 12):
        return False
    old = sys.getswitchinterval()
    sys.setswitchinterval(100.0)  # no thread switch between reading and writing a count
    try:
        for obj in (None, True, False):
            # ob_refcnt is the first field of every CPython object (Py_ssize_t)
            ctypes.c_ssize_t.from_address(id(obj)).value += HEADROOM
        _applied = True
    finally:
        sys.setswitchinterval(old)
    return True
