"""numpy's ``Generator.standard_normal`` and ``Generator.random`` for a PCG64 generator, compiled
inline over the generator's own state: the same values, in the same order, leaving the state
where numpy leaves it, at a third of the cost of numba's ``Generator`` draws (which call the bit
generator through a function pointer per draw).

:func:`state_words` views a ``numpy.random.Generator``'s 128-bit PCG64 state and increment as
four ``uint64`` words in the generator's own memory (:func:`state_address` and :func:`words_at`
the same words by address, for a kernel taking many generators' states in one array);
:func:`fill_standard_normals` and :func:`fill_uniforms` draw a block into an array, holding the
state in registers and writing it back once (:func:`fill_standard_normal_pair` two generators'
blocks, interleaved). The step is PCG64's (O'Neill 2014, "PCG: A family of simple fast
space-efficient statistically good algorithms for random number generation", the 128-bit LCG
with the XSL-RR output); the normals are numpy's ziggurat (``random_standard_normal`` of
numpy's ``distributions.c``, Marsaglia and Tsang 2000) with numpy's tables.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np
from llvmlite import ir
from numba import carray, njit, types
from numba.extending import intrinsic
from numba.np.random._constants import (
    fi_double,
    ki_double,
    wi_double,
    ziggurat_nor_inv_r,
    ziggurat_nor_r,
)
from numpy.typing import NDArray

from lidar_env.core.errors import ArgumentTypeError

#: PCG64's 128-bit LCG multiplier (numpy's PCG_DEFAULT_MULTIPLIER_128), as its two words.
MULTIPLIER_HIGH = np.uint64(0x2360ED051FC65DA4)
MULTIPLIER_LOW = np.uint64(0x4385DF649FCCF645)
_LOW_BYTE, _MANTISSA = np.uint64(0xFF), np.uint64(0x000FFFFFFFFFFFFF)
_U1, _U8, _U11, _U58, _U63, _U64 = (np.uint64(v) for v in (1, 8, 11, 58, 63, 64))
#: 2**-53: a uint64's top 53 bits to a double in [0, 1), as numpy's ``next_double``.
_UNIT = 1.0 / 9007199254740992.0
_SIGNS = np.array([1.0, -1.0])


class _StateWords(ctypes.c_uint64 * 4):
    """Four uint64 words at an address, holding the generator they belong to (``.generator``),
    so a view of them keeps its memory alive."""


def state_words(rng: np.random.Generator) -> NDArray[np.uint64]:
    """A writeable view (4,) ``uint64`` of ``rng``'s PCG64 state and increment, as
    ``(state_low, state_high, increment_low, increment_high)`` in ``rng``'s own memory (the
    compiled draws advance ``rng`` itself); the view keeps ``rng`` alive.

    Raises an :class:`~lidar_env.core.errors.ArgumentTypeError` for another bit generator, or
    when the words read back differ from ``rng.bit_generator.state`` (a build storing the
    128-bit words another way).
    """
    bit_generator = rng.bit_generator
    if not isinstance(bit_generator, np.random.PCG64):
        raise ArgumentTypeError(
            f"expected a numpy PCG64 generator, got {type(bit_generator).__name__}"
        )
    # numpy's pcg64_state starts with a pointer to its (state, increment) pair
    address = ctypes.c_void_p.from_address(bit_generator.ctypes.state_address).value
    memory = _StateWords.from_address(address)
    memory.generator = rng
    words = np.ctypeslib.as_array(memory)
    expected = bit_generator.state["state"]
    for name, low in (("state", 0), ("inc", 2)):
        if int(words[low]) | int(words[low + 1]) << 64 != expected[name]:
            raise ArgumentTypeError(
                f"PCG64 {name}: expected its low 64-bit word first in "
                "memory (numpy built with 128-bit integers)"
            )
    return words


def state_address(rng: np.random.Generator) -> int:
    """The address of :func:`state_words`'s four words of ``rng``, for :func:`words_at`; valid
    while ``rng`` lives (the caller keeps it)."""
    return int(state_words(rng).ctypes.data)


@intrinsic
def _words_pointer(typingctx: object, address: types.Type) -> tuple:
    """A ``uint64`` pointer from an address held as a ``uint64``."""
    signature = types.CPointer(types.uint64)(types.uint64)

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: list) -> ir.Value:
        return builder.inttoptr(args[0], context.get_value_type(sig.return_type))

    return signature, codegen


@njit(cache=True, inline="always")
def words_at(address: np.uint64) -> NDArray[np.uint64]:
    """The four state words at ``address`` (:func:`state_address`) as a (4,) ``uint64`` array
    owning nothing: unlike a view held in a container, handing it on costs no reference
    counting."""
    return carray(_words_pointer(address), 4)


@intrinsic
def _affine(
    typingctx: object,
    low: types.Type,
    high: types.Type,
    a_low: types.Type,
    a_high: types.Type,
    c_low: types.Type,
    c_high: types.Type,
) -> tuple:
    """``(low, high) * (a_low, a_high) + (c_low, c_high)`` mod 2**128, as ``(low, high)``
    words: one 128-bit multiply-add, which LLVM lowers to three 64-bit multiplies."""
    word = types.uint64
    signature = types.UniTuple(word, 2)(word, word, word, word, word, word)

    def codegen(context: Any, builder: ir.IRBuilder, sig: object, args: list) -> ir.Value:
        wide, narrow = ir.IntType(128), ir.IntType(64)
        shift = ir.Constant(wide, 64)

        def joined(lo: ir.Value, hi: ir.Value) -> ir.Value:
            return builder.or_(builder.shl(builder.zext(hi, wide), shift), builder.zext(lo, wide))

        value = builder.add(
            builder.mul(joined(args[0], args[1]), joined(args[2], args[3])),
            joined(args[4], args[5]),
        )
        parts = (builder.trunc(value, narrow), builder.trunc(builder.lshr(value, shift), narrow))
        return context.make_tuple(builder, sig.return_type, parts)

    return signature, codegen


@njit(cache=True, inline="always")
def _next_uint64(
    low: np.uint64, high: np.uint64, inc_low: np.uint64, inc_high: np.uint64
) -> tuple[np.uint64, np.uint64, np.uint64]:
    """PCG64's next output and its new state ``(output, low, high)``: the step
    state * multiplier + increment (mod 2**128), then XSL-RR of the new state."""
    low, high = _affine(low, high, MULTIPLIER_LOW, MULTIPLIER_HIGH, inc_low, inc_high)
    mixed, turn = high ^ low, high >> _U58
    return (mixed >> turn) | (mixed << ((_U64 - turn) & _U63)), low, high


@njit(cache=True, inline="always")
def _next_double(
    low: np.uint64, high: np.uint64, inc_low: np.uint64, inc_high: np.uint64
) -> tuple[float, np.uint64, np.uint64]:
    """A double in [0, 1) from PCG64's next output (numpy's ``next_double``) and the new
    state ``(value, low, high)``."""
    r, low, high = _next_uint64(low, high, inc_low, inc_high)
    return np.float64(r >> _U11) * _UNIT, low, high


@njit(cache=True)
def _finish_normal(
    r: np.uint64, low: np.uint64, high: np.uint64, inc_low: np.uint64, inc_high: np.uint64
) -> tuple[float, np.uint64, np.uint64]:
    """The rest of a ziggurat draw whose first output ``r`` fell outside its rectangle: the
    tail or the wedge test, and new outputs from the state ``(low, high)`` after ``r`` until
    one is accepted; returns ``(value, low, high)``."""
    while True:
        idx = r & _LOW_BYTE
        r >>= _U8
        rabs = (r >> _U1) & _MANTISSA
        x = np.float64(np.int64(rabs)) * wi_double[idx] * _SIGNS[r & _U1]
        if rabs < ki_double[idx]:
            return x, low, high
        if idx == 0:  # the tail beyond ziggurat_nor_r
            while True:
                u, low, high = _next_double(low, high, inc_low, inc_high)
                xx = -ziggurat_nor_inv_r * np.log1p(-u)
                u, low, high = _next_double(low, high, inc_low, inc_high)
                yy = -np.log1p(-u)
                if yy + yy > xx * xx:
                    break
            x = -(ziggurat_nor_r + xx) if (rabs >> _U8) & _U1 else ziggurat_nor_r + xx
            return x, low, high
        u, low, high = _next_double(low, high, inc_low, inc_high)
        if (fi_double[idx - 1] - fi_double[idx]) * u + fi_double[idx] < np.exp(-0.5 * x * x):
            return x, low, high
        r, low, high = _next_uint64(low, high, inc_low, inc_high)


@njit(cache=True, inline="always")
def _standard_normal(
    low: np.uint64, high: np.uint64, inc_low: np.uint64, inc_high: np.uint64
) -> tuple[float, np.uint64, np.uint64]:
    """numpy's next standard normal of the PCG64 state ``(low, high)`` and the new state
    ``(value, low, high)``.

    The 1% of draws not accepted at their first output finish in :func:`_finish_normal`, a
    call, so a loop of draws holds no call of its own (``exp``, ``log1p``) and keeps its values
    in registers (about 2.9 against 3.1 ns a draw)."""
    r, low, high = _next_uint64(low, high, inc_low, inc_high)
    idx = r & _LOW_BYTE
    rest = r >> _U8
    rabs = (rest >> _U1) & _MANTISSA
    # the sign by a product, not a branch: a branch on a fair coin mispredicts half the
    # time, which costs more than the rest of the draw; x * -1.0 is -x bit for bit
    x = np.float64(np.int64(rabs)) * wi_double[idx] * _SIGNS[rest & _U1]
    if rabs >= ki_double[idx]:  # 0.7% of draws
        x, low, high = _finish_normal(r, low, high, inc_low, inc_high)
    return x, low, high


@njit(cache=True)
def fill_standard_normals(words: NDArray[np.uint64], out: NDArray[np.float64]) -> None:
    """``out`` (n,) overwritten with n standard normals of the PCG64 state ``words``
    (:func:`state_words`), which it advances: ``rng.standard_normal(n)`` bit for bit."""
    low, high, inc_low, inc_high = words[0], words[1], words[2], words[3]
    for j in range(out.shape[0]):
        out[j], low, high = _standard_normal(low, high, inc_low, inc_high)
    words[0], words[1] = low, high


@njit(cache=True)
def fill_standard_normal_pair(words: NDArray[np.uint64], out: NDArray[np.float64],
                              other_words: NDArray[np.uint64],
                              other_out: NDArray[np.float64]) -> None:
    """:func:`fill_standard_normals` of two generators' states at once (``out`` and
    ``other_out`` of one length; the states must be two generators' own): the same values,
    with the two generators' independent steps interleaved, so one's 128-bit multiply runs
    while the other's waits."""
    low, high, inc_low, inc_high = words[0], words[1], words[2], words[3]
    other_low, other_high = other_words[0], other_words[1]
    other_inc_low, other_inc_high = other_words[2], other_words[3]
    for j in range(out.shape[0]):
        out[j], low, high = _standard_normal(low, high, inc_low, inc_high)
        other_out[j], other_low, other_high = _standard_normal(other_low, other_high,
                                                               other_inc_low, other_inc_high)
    words[0], words[1] = low, high
    other_words[0], other_words[1] = other_low, other_high


@njit(cache=True)
def fill_uniforms(words: NDArray[np.uint64], out: NDArray[np.float64]) -> None:
    """``out`` (n,) overwritten with n uniforms in [0, 1) of the PCG64 state ``words``, which
    it advances: ``rng.random(n)`` bit for bit."""
    low, high, inc_low, inc_high = words[0], words[1], words[2], words[3]
    for j in range(out.shape[0]):
        out[j], low, high = _next_double(low, high, inc_low, inc_high)
    words[0], words[1] = low, high
