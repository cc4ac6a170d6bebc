"""Count what every engine kernel and ``ti.func`` receives, tuple members included.

Run in a fresh interpreter (``python tests/kernel_widths.py``): it wraps the compiler's
``Kernel.__call__`` and ``Func.__call__``, steps every model of the family on the lane path
(96x80 frames), on the generic path (frames narrower than two lane vectors) and on event
bins, and prints a JSON object ``{"module:function": widest call}``. A call's width counts
every argument, and each member of a tuple argument (recursively) as one: a context of
14 arrays is 14 parameters.
"""
from __future__ import annotations

import dataclasses
import json
import os
import sys
import types

import numpy as np


def leaves(value) -> int:
    """How many parameters ``value`` stands for: 1, or the members of a tuple, list, namespace or
    dataclass instance or object with ``__slots__`` (a context however it is spelt), recursively."""
    if isinstance(value, (tuple, list)):
        return sum(leaves(v) for v in value)
    if isinstance(value, types.SimpleNamespace):
        return sum(leaves(v) for v in vars(value).values())
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return sum(leaves(getattr(value, f.name)) for f in dataclasses.fields(value))
    slots = [s for cls in type(value).__mro__ for s in getattr(cls, "__slots__", ())]
    if slots and not isinstance(value, type):  # an object of named members (the engine's cell accessor)
        return sum(leaves(getattr(value, s)) for s in slots)
    return 1


def instrument(widths: dict[str, int]) -> None:
    """Record the width of every call of a kernel or ti.func defined under ``kernels/``."""
    compiler = os.environ.get("CDNF_TI_COMPILER", "taichi")
    kernel_impl = __import__(f"{compiler}.lang.kernel_impl", fromlist=["Kernel", "Func"])

    for cls in (kernel_impl.Kernel, kernel_impl.Func):
        original = cls.__call__

        def call(self, *args, __original=original, **kwargs):
            fn = self.func
            path = getattr(getattr(fn, "__code__", None), "co_filename", "")
            if os.sep + "kernels" + os.sep in path:
                key = f"{os.path.basename(path)}:{fn.__name__}"
                widths[key] = max(widths.get(key, 0), leaves(args) + leaves(tuple(kwargs.values())))
            return __original(self, *args, **kwargs)

        cls.__call__ = call


def exercise() -> None:
    """Step every model on both paths and on event bins: random frames (the LGMD family's
    feed-forward inhibition holds, so its layers are skipped) and a looming square (they run)."""
    from cdnf_ti import create_model
    from cdnf_ti.models.registry import MODELS
    from cdnf_ti.stimuli.basic import basic_stimulus

    rng = np.random.default_rng(0)
    for shape in ((80, 96), (40, 48)):
        looming = basic_stimulus("dark_looming", height=shape[0], width=shape[1], backend="numpy")
        clips = ([rng.integers(0, 256, shape, dtype=np.uint8) for _ in range(3)], list(looming.frames())[:12])
        for name in MODELS:
            for frames in clips:
                model = create_model(name)
                model.run(frames)
                if model.takes_events:
                    p_on = (rng.random(shape) < 0.1) * 0.15
                    p_off = (rng.random(shape) < 0.1) * 0.15
                    model.step_on_off(p_on, p_off)


if __name__ == "__main__":
    found: dict[str, int] = {}
    instrument(found)
    exercise()
    json.dump(dict(sorted(found.items(), key=lambda kv: -kv[1])), sys.stdout, indent=1)
    print()
