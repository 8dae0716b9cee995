"""Shared-memory frame slots between the pipeline child process and the UI process (no Qt).

The child writes each display frame (BGRA uint8) into a free slot of a
`FrameRing` (`claim` a slot, write the picture there in place, `publish` it;
`write` copies a finished array) and sends only the slot's number over the pipe; the UI process
maps the same memory once (`RingReader`) and wraps the slot in place, so a
720p frame crosses the process boundary without a copy. Ownership is one
flag byte per slot at the ring's start: the child sets it (0 -> 1) after
writing a slot, the UI clears it (1 -> 0) when it no longer shows or holds
that frame; each flag has one writer per transition, so no lock is needed.
When no slot is free the child drops the frame (latest frame wins).

Cleanup: the UI unlinks the segment's name as soon as it has mapped it (its
mapping stays valid until the last array over it is gone); the child unlinks
every ring it created when it ends, which covers a ring the UI never saw.
"""

from __future__ import annotations

import mmap
from multiprocessing import shared_memory

import numpy as np

HEADER = 64  # flag bytes (one per slot) before the first slot; keeps slots 64-byte aligned
SLOTS = 4    # shown + waiting in the UI's slot + one or two messages in flight


class FrameRing:
    """Child side: `count` slots of `slot_bytes` each in one new shared-memory segment."""

    def __init__(self, slot_bytes: int, count: int = SLOTS):
        self.slot_bytes, self.count = int(slot_bytes), int(count)
        self.shm = shared_memory.SharedMemory(create=True, size=HEADER + self.count * self.slot_bytes)
        self.name = self.shm.name
        self._next = 0
        self._claimed: set[int] = set()  # slots being written here (flag still 0: the UI leaves them alone)
        self.dropped = 0  # frames not written because every slot was still held by the UI

    def fits(self, array: np.ndarray) -> bool:
        return array.nbytes <= self.slot_bytes

    def claim(self, shape: tuple) -> tuple[int, np.ndarray] | None:
        """A free slot to write a frame of `shape` (uint8) into: (index, the array over it), or None (counted
        as dropped) when the UI holds every slot. `publish` or `abandon` it."""
        if int(np.prod(shape)) > self.slot_bytes:
            raise ValueError(f"a frame of {shape} does not fit the ring's {self.slot_bytes}-byte slots")
        flags = np.ndarray((self.count,), np.uint8, self.shm.buf)
        try:
            for k in range(self.count):
                i = (self._next + k) % self.count
                if flags[i] == 0 and i not in self._claimed:
                    break
            else:
                self.dropped += 1
                return None
        finally:
            del flags
        self._claimed.add(i)
        self._next = (i + 1) % self.count
        return i, np.ndarray(tuple(shape), np.uint8, self.shm.buf, HEADER + i * self.slot_bytes)

    def publish(self, slot: int) -> None:
        """The frame in claimed `slot` is written: mark it held (the UI releases it)."""
        self._claimed.discard(slot)
        flags = np.ndarray((self.count,), np.uint8, self.shm.buf)
        flags[slot] = 1
        del flags

    def abandon(self, slot: int) -> None:
        """Claimed `slot` was not sent after all: free again."""
        self._claimed.discard(slot)

    def write(self, array: np.ndarray) -> int | None:
        """Copy `array` into a free slot and mark it held; its index, or None when none is free."""
        got = self.claim(array.shape)
        if got is None:
            return None
        i, dst = got
        np.copyto(dst, array)
        del dst
        self.publish(i)
        return i

    def close(self) -> None:
        """Unlink (the UI may have done so already) and unmap; a mapping still under a frame array here is
        left to go with the process."""
        try:
            self.shm.unlink()
        except FileNotFoundError:
            pass
        try:
            self.shm.close()
        except BufferError:
            pass  # a display picture still points into it


class RingReader:
    """UI side: the child's ring mapped once; its name is unlinked right away (no leak if either side dies)."""

    def __init__(self, name: str, slot_bytes: int, count: int):
        shm = shared_memory.SharedMemory(name=name)
        try:
            # an own mapping, so arrays over it keep it alive on their own (SharedMemory.close refuses
            # while arrays exist)
            self._map = mmap.mmap(shm._fd, HEADER + count * slot_bytes)
        finally:
            shm.close()
            shm.unlink()
        self.name, self.slot_bytes, self.count = name, slot_bytes, count
        self.flags = np.frombuffer(self._map, np.uint8, count)

    def view(self, slot: int, shape: tuple) -> np.ndarray:
        """The frame in `slot` in place (valid until `release(slot)`)."""
        n = int(np.prod(shape))
        return np.frombuffer(self._map, np.uint8, n, HEADER + slot * self.slot_bytes).reshape(shape)

    def release(self, slot: int) -> None:
        """The UI no longer holds the frame in `slot`: the child may write it again."""
        self.flags[slot] = 0
