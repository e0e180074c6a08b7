"""A keyer's matte held in fewer bytes while a frame set's results wait for the write (issue 24: a worker's
memory). A matte is 0 on the screen and 1 on the subject but for the ramp between them, a few % of a
presenter's frame: :class:`PackedPlane` keeps a byte per pixel saying 0, 1 or other, and the others' float32
values, and gives back the same bits (+0.0 and 1.0 are told apart from the rest by their bit patterns, so
-0.0, NaN and every other value come back as they were). :class:`PackedField` makes a dataclass field hold
its plane so packed: set with an array, read as an array, made on each read."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

ZERO, ONE, OTHER = 0, 1, 2
_ONE_BITS = np.float32(1.0).view(np.uint32)


@dataclass(frozen=True)
class PackedPlane:
    code: NDArray[np.uint8]  # ZERO, ONE or OTHER per pixel
    others: F32  # the OTHER pixels' values, in the plane's (row-major) order

    @classmethod
    def of(cls, plane: NDArray[Any]) -> PackedPlane:
        a = np.ascontiguousarray(plane, np.float32)
        bits = a.view(np.uint32)
        code = np.full(a.shape, OTHER, np.uint8)
        code[bits == 0] = ZERO
        code[bits == _ONE_BITS] = ONE
        return cls(code, a[code == OTHER])

    def plane(self) -> F32:
        out = (self.code == ONE).astype(np.float32)
        if self.others.size:
            out[self.code == OTHER] = self.others
        return out

    def any_below_one(self) -> bool:
        """``bool((self.plane() < 1).any())`` without making the plane."""
        return bool((self.code == ZERO).any() or (self.others < 1).any())

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.code.shape)

    @property
    def nbytes(self) -> int:
        return int(self.code.nbytes + self.others.nbytes)


class PackedField:
    """A dataclass field (no default) whose float32 plane is held as a :class:`PackedPlane` (see the module):
    the dataclass's ``__init__`` and every assignment pack it, every read makes the plane again (a new array:
    write to it and assign it back). :meth:`held` gives what is held."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.slot = f"_{name}_packed"

    def __get__(self, obj: object | None, owner: type | None = None) -> F32:
        if obj is None:
            raise AttributeError("no default")  # how a dataclass learns a descriptor field has none
        packed: PackedPlane = obj.__dict__[self.slot]
        return packed.plane()

    def __set__(self, obj: object, value: NDArray[Any] | PackedPlane) -> None:
        obj.__dict__[self.slot] = value if isinstance(value, PackedPlane) else PackedPlane.of(value)

    @staticmethod
    def held(obj: object, name: str) -> PackedPlane:
        """What ``obj``'s field ``name`` holds."""
        packed: PackedPlane = obj.__dict__[f"_{name}_packed"]
        return packed
