"""A frame set's results held in fewer bytes while they wait for the write (issue 24: a worker's memory). In a
presenter's frame most of every plane is one value: the screen's (disparity +inf, confidence 0, every mask
False) and, for the keyer's matte, 0 or 1 but for a ramp a few % wide.

- :class:`PackedPlane` (the matte): a byte per pixel saying 0, 1 or other, and the others' float32 values;
- :class:`FillPlane` (disparity, confidence): a bit per pixel saying whether it holds the plane's fill value,
  and the others' values;
- :class:`BitPlane` (a mask): a bit per pixel.

Each gives back the same bits (values are told apart by their bit patterns, so -0.0, NaN and every other
value come back as they were). :class:`PackedField` makes a dataclass field hold its plane so packed: set
with an array, read as a new read-only array made on each read (an in-place write fails loudly rather than
being lost: make the plane, change it, assign it back).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
A = TypeVar("A", bound=NDArray[Any])

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


@dataclass(frozen=True)
class FillPlane:
    shape: tuple[int, ...]
    fill: np.float32  # the value most pixels hold
    other: NDArray[np.uint8]  # per pixel, packed 8 to a byte (``np.packbits``): its bits are not the fill's
    others: F32  # those pixels' values, in the plane's (row-major) order

    @classmethod
    def of(cls, plane: NDArray[Any], fill: float) -> FillPlane:
        a = np.ascontiguousarray(plane, np.float32)
        f = np.float32(fill)
        other = a.view(np.uint32) != f.view(np.uint32)
        return cls(tuple(a.shape), f, np.packbits(other, axis=None), a[other])

    @classmethod
    def filling(cls, fill: float) -> Callable[[NDArray[Any]], FillPlane]:
        """A packer for :class:`PackedField`: planes packed around ``fill``."""
        return lambda plane: cls.of(plane, fill)

    def plane(self) -> F32:
        out = np.full(self.shape, self.fill, np.float32)
        if self.others.size:
            out[_unpacked(self.other, self.shape)] = self.others
        return out

    @property
    def nbytes(self) -> int:
        return int(self.other.nbytes + self.others.nbytes)


@dataclass(frozen=True)
class BitPlane:
    shape: tuple[int, ...]
    bits: NDArray[np.uint8]  # the mask, 8 pixels to a byte (``np.packbits``)

    @classmethod
    def of(cls, plane: NDArray[Any]) -> BitPlane:
        a = np.asarray(plane, bool)
        return cls(tuple(a.shape), np.packbits(a, axis=None))

    def plane(self) -> NDArray[np.bool_]:
        return _unpacked(self.bits, self.shape)

    @property
    def nbytes(self) -> int:
        return int(self.bits.nbytes)


def _unpacked(bits: NDArray[np.uint8], shape: tuple[int, ...]) -> NDArray[np.bool_]:
    return np.unpackbits(bits, count=math.prod(shape)).view(np.bool_).reshape(shape)


class Packed(Protocol):
    def plane(self) -> NDArray[Any]: ...

    @property
    def nbytes(self) -> int: ...


class PackedField(Generic[A]):
    """A dataclass field whose plane is held packed by ``pack`` (see the module): the dataclass's ``__init__``
    and every assignment pack it, every read makes the plane again, read-only. With ``empty``, the field's
    default is ``None``, which holds ``empty()``. :meth:`held` gives what is held."""

    def __init__(self, pack: Callable[[Any], Packed], empty: Callable[[], A] | None = None) -> None:
        self.pack = pack
        self.empty = empty

    def __set_name__(self, owner: type, name: str) -> None:
        self.name, self.slot = name, f"_{name}_packed"

    def __get__(self, obj: object | None, owner: type | None = None) -> A:
        if obj is None:
            if self.empty is None:
                raise AttributeError("no default")  # how a dataclass learns a descriptor field has none
            return None  # type: ignore[return-value]  # the default, as the dataclass sees it
        out = self.held(obj, self.name).plane()
        out.flags.writeable = False
        return out  # type: ignore[return-value]

    def __set__(self, obj: object, value: A | Packed | None) -> None:
        if value is None:
            assert self.empty is not None, "no default"
            value = self.empty()
        obj.__dict__[self.slot] = value if not isinstance(value, np.ndarray) else self.pack(value)

    @staticmethod
    def held(obj: object, name: str) -> Packed:
        """What ``obj``'s field ``name`` holds."""
        packed: Packed = obj.__dict__[f"_{name}_packed"]
        return packed
