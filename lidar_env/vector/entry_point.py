"""Calling a numba kernel without its dispatcher's per-call type resolution."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


class EntryPoint:
    """Calls a numba dispatcher through the machine code of the one signature it is first
    called with.

    The dispatcher resolves the argument types at every call, and for the nested typed lists
    and tuples of :mod:`lidar_env.vector.kernel`'s kernels that costs ~160 us per call
    (hashing the types), against ~10 us for the call itself; the arguments' types never change
    for one env, so they are resolved once. Every later call must pass arguments of the same
    types.
    """

    def __init__(self, dispatcher: Any) -> None:
        self.dispatcher = dispatcher
        self._entry: Callable[..., Any] | None = None

    def __getstate__(self) -> dict[str, str]:
        # by name: the machine code is resolved again (from numba's cache) at the first call
        return {"module": self.dispatcher.py_func.__module__,
                "name": self.dispatcher.py_func.__name__}

    def __setstate__(self, state: dict[str, str]) -> None:
        module = importlib.import_module(state["module"])
        self.__init__(getattr(module, state["name"]))

    def resolve(self, *args: Any) -> Callable[..., Any]:
        """The machine code for the types of ``args`` (those of the first call), to call with
        arguments of those types directly."""
        if self._entry is None:
            signature = tuple(self.dispatcher.typeof_pyval(a) for a in args)
            self._entry = self.dispatcher.compile(signature)
        return self._entry

    def __call__(self, *args: Any) -> Any:
        return self.resolve(*args)(*args)
