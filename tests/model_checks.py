"""The check the compiled models' tests share: a compiled model and its float64 reference, stepped over the
same input, agree on their output within a tolerance and on the alert on every frame.

A reference is the model's streaming NumPy oracle (``cdnf_ti/<name>_reference.py``): ``step(frame)``,
``step_on_off(p_on, p_off)`` for an event bin, each returning a record (a dataclass with the output and
``alert``). The helpers here only drive and compare; the equations stay in the reference.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping, Sequence

import cv2
import numpy as np
import pytest


def input_shape(inputs: Sequence) -> tuple[int, int]:
    """``(H, W)`` of the first input: a frame (H, W) or (H, W, 3), or an event bin ``(p_on, p_off)``."""
    first = inputs[0][0] if isinstance(inputs[0], tuple) else inputs[0]
    return tuple(np.shape(first)[:2])


def reference_run(reference: Any, inputs: Sequence) -> dict[str, np.ndarray]:
    """Step ``reference`` over ``inputs`` (frames, or event bins ``(p_on, p_off)`` through ``step_on_off``);
    each field of its records as an array over the inputs, shape (T,)."""
    steps = [reference.step_on_off(*x) if isinstance(x, tuple) else reference.step(x) for x in inputs]
    return {f.name: np.array([getattr(s, f.name) for s in steps]) for f in dataclasses.fields(steps[0])}


def agreement(trace: Any, ref: Mapping[str, np.ndarray], output: str, absolute: Sequence[str] = (),
              relative: Mapping[str, float] | None = None, peak: str | None = None) -> dict:
    """How far a compiled model's trace is from the reference's run, column by column.

    Parameters
    ----------
    trace : Trace
        The compiled model's trace over T inputs.
    ref : dict of str to ndarray, shape (T,)
        The reference's run over the same inputs (:func:`reference_run`), with its ``alert`` column.
    output : str
        The reference's column of the model's output.
    absolute : sequence of str
        Diagnostics compared by their largest absolute difference.
    relative : dict of str to float
        Diagnostics compared by their largest difference relative to ``max(reference, floor)``.
    peak : str, optional
        A reference column whose largest value is reported as ``"peak"``.

    Returns
    -------
    dict
        ``output`` and each diagnostic: the largest difference (float); ``alerts_equal``: the alert equal on
        every frame; ``alerts``: the reference's alert count; ``peak`` when asked. Plain Python values.
    """
    out = {output: float(np.max(np.abs(trace.output - ref[output])))}
    for name in absolute:
        out[name] = float(np.max(np.abs(trace.diagnostics[name] - ref[name])))
    for name, floor in (relative or {}).items():
        out[name] = float(np.max(np.abs(trace.diagnostics[name] - ref[name]) / np.maximum(ref[name], floor)))
    out["alerts_equal"] = bool(np.array_equal(trace.spike, ref["alert"]))
    out["alerts"] = int(np.sum(ref["alert"]))
    if peak is not None:
        out["peak"] = float(np.max(ref[peak]))
    return out


def compare(model: Any, reference: Callable[[int, int], Any], inputs: Sequence, output: str, *,
            reference_inputs: Sequence | None = None, **columns: Any) -> dict:
    """Run ``model`` (fresh or reset by its run) and a reference over ``inputs`` and report their
    :func:`agreement`.

    Parameters
    ----------
    model : Model
        The compiled model.
    reference : callable
        ``reference(H, W)``: a new reference for inputs of that size (px).
    inputs : sequence
        Frames, or event bins ``(p_on, p_off)``.
    output : str
        The reference's column of the model's output.
    reference_inputs : sequence, optional
        What the reference steps over instead of ``inputs`` (e.g. the emulator's event maps of the frames).
    **columns
        ``absolute``, ``relative``, ``peak`` of :func:`agreement`.
    """
    trace = model.run(inputs)
    ref = reference_run(reference(*input_shape(inputs)), inputs if reference_inputs is None else reference_inputs)
    return agreement(trace, ref, output, **columns)


def assert_agrees(r: dict, **tolerance: float) -> None:
    """Each column named in ``tolerance`` below its tolerance in :func:`agreement`'s ``r``, and the alert equal
    on every frame."""
    for name, tol in tolerance.items():
        assert r[name] < tol, r
    assert r["alerts_equal"], r


def clip_frames(shared_real: Any, clip: str, stop: int, start: int = 0) -> list[np.ndarray]:
    """Frames ``start .. stop - 1`` of a development clip (BGR uint8, as read; fewer where it ends); skips the
    test, saying why, when the shared clips are not here."""
    path = shared_real / clip if shared_real else None
    if path is None or not path.exists():
        pytest.skip(f"the development clip {clip} is not here (the shared data/real folder is absent)")
    cap = cv2.VideoCapture(str(path))
    frames = []
    for k in range(stop):
        ok, f = cap.read()
        if not ok:
            break
        if k >= start:
            frames.append(f)
    cap.release()
    return frames
