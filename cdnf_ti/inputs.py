"""Resolve an input spec to a frame source: a file/folder/.npy path or a generated stimulus.

Generated stimuli are named ``stim:NAME`` with optional query parameters::

    stim:dark_looming
    stim:light_translating?coherence=0.2&seed=3&size=240&fps=30

``NAME`` is one of :data:`cdnf_ti.stimuli.basic.BASIC_STIMULI`. Parameters:
``coherence`` (default 1: the coherent stimulus), ``seed`` (0), ``size`` (sets
height = width; ``start_half_size`` defaults to ``min(height, width) / 60``,
:func:`cdnf_ti.stimuli.basic.default_start_half_size`, so the geometry matches
the 600 px default), ``height``, ``width``, ``fps``,
``duration``, ``start_half_size``, ``end_half_size``, ``bar_width``,
``expansion`` (``inverse`` or ``linear``), ``object_grey``,
``background_grey``, ``speed`` (translating bar, px/s), ``scatter`` (``flicker``
or ``static``: how displaced dots of an incoherent stimulus behave,
:class:`cdnf_ti.stimuli.incoherent.IncoherentStimulus`). ``stim:grating`` is the
drifting grating (:class:`cdnf_ti.stimuli.grating.GratingStimulus`: ``size``,
``height``, ``width``, ``fps``, ``duration``, ``period``, ``bar_width``,
``speed``, ``orientation``, ``bar_grey``, ``background_grey``, ``seed``). Frames
are generated on the fly; nothing is written to disk.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qsl

from .errors import InputError, UserError
from .frames import FrameSource, open_source
from .limits import check_frame_size
from .stimuli.basic import BASIC_STIMULI, basic_stimulus
from .stimuli.grating import GratingStimulus
from .stimuli.incoherent import IncoherentStimulus

STIM_PREFIX = "stim:"
_INT_KEYS = ("seed", "size", "height", "width", "bar_width", "period")
_FLOAT_KEYS = ("coherence", "fps", "duration", "start_half_size", "end_half_size", "speed", "object_grey",
               "background_grey", "bar_grey")
_TEXT_KEYS = ("expansion", "orientation", "scatter")
#: Generated stimuli beside the six basic ones.
GRATING = "grating"


@dataclass
class GeneratedSource(FrameSource):
    """A :class:`~cdnf_ti.frames.FrameSource` over a generated stimulus.

    Attributes
    ----------
    stimulus : object
        The generator (``BasicStimulus`` or ``IncoherentStimulus``).
    label : str
        File-name-safe clip name, e.g. ``dark_looming_c0.2_s3``.
    """

    stimulus: Any = None
    label: str = ""

    @property
    def name(self) -> str:
        return self.label


def parse_stim_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"stim:NAME?k=v&..."`` -> ``(NAME, {k: typed value})``.

    Raises
    ------
    InputError
        Unknown stimulus, unknown or malformed parameter.
    """
    body = spec[len(STIM_PREFIX):] if spec.startswith(STIM_PREFIX) else spec
    name, _, query = body.partition("?")
    if name not in BASIC_STIMULI and name != GRATING:
        raise InputError(spec, f"unknown stimulus {name!r}; choose one of {', '.join(BASIC_STIMULI + (GRATING,))}")
    params: dict[str, Any] = {}
    known = _INT_KEYS + _FLOAT_KEYS + _TEXT_KEYS
    for key, val in parse_qsl(query, keep_blank_values=True, strict_parsing=False):
        if key not in known:
            raise InputError(spec, f"unknown parameter {key!r}; known: {', '.join(known)}")
        if key in _TEXT_KEYS:
            params[key] = val
            continue
        try:
            params[key] = int(val) if key in _INT_KEYS else float(val)
        except ValueError:
            raise InputError(spec, f"parameter {key}={val!r} is not a number") from None
    return name, params


def make_stimulus(name: str, params: dict[str, Any]):
    """Build the generator for ``name`` and parsed ``params`` (see module docstring)."""
    p = dict(params)
    coherence = float(p.pop("coherence", 1.0))
    seed = int(p.pop("seed", 0))
    scatter = p.pop("scatter", None)
    size = p.pop("size", None)
    if size is not None:
        p.setdefault("height", size)
        p.setdefault("width", size)
    if name == GRATING:
        if "coherence" in params or scatter is not None:
            raise ValueError("a grating has no incoherent version (coherence and scatter apply to the basic stimuli)")
        return GratingStimulus(seed=seed if "seed" in params else None, **p)
    base = basic_stimulus(name, **p)
    if coherence == 1.0 and "coherence" not in params and scatter is None:
        return base
    return IncoherentStimulus(base, coherence, seed, scatter=scatter or "flicker")


def stimulus_label(name: str, params: dict[str, Any]) -> str:
    """File-name-safe label: ``NAME`` plus ``_c<coherence>_s<seed>`` and other set parameters."""
    parts = [name]
    if "coherence" in params:
        parts.append(f"c{params['coherence']:g}")
    if "seed" in params:
        parts.append(f"s{params['seed']}")
    for k in sorted(params):
        if k not in ("coherence", "seed"):
            v = params[k]
            parts.append(f"{k}{v}" if isinstance(v, str) else f"{k}{v:g}")
    return "_".join(parts)


def check_stim_size(spec: str, params: dict[str, Any]) -> None:
    """Reject a stimulus whose frames could not be held here, before it is built (:mod:`cdnf_ti.limits`)."""
    size = params.get("size", 600)
    h, w = params.get("height", size), params.get("width", size)
    try:
        check_frame_size(h, w, what="frame size")
    except UserError as e:
        raise InputError(spec, str(e)) from None


def resolve_input(spec: str | os.PathLike, fps: float | None = None, color_order: str = "bgr") -> FrameSource:
    """Open ``spec``: ``stim:...`` generates a stimulus, anything else goes to :func:`~cdnf_ti.frames.open_source`.

    ``fps`` and ``color_order`` are passed to :func:`~cdnf_ti.frames.open_source`
    (a generated stimulus takes its frame rate from its ``fps`` parameter).

    Returns
    -------
    FrameSource
        Re-iterable; each iteration streams the frames again (generated
        stimuli: float32 (H, W) in [0, 1]).

    Raises
    ------
    InputError
        Bad path or bad stimulus spec, or a stimulus too large for this
        machine (:mod:`cdnf_ti.limits`); one-line message naming the input.
    """
    s = str(spec)
    if not s.startswith(STIM_PREFIX):
        return open_source(spec, fps=fps, color_order=color_order)
    name, params = parse_stim_spec(s)
    check_stim_size(s, params)
    try:
        stim = make_stimulus(name, params)
    except (ValueError, TypeError) as e:
        raise InputError(s, str(e)) from None
    return GeneratedSource(s, float(stim.fps), int(stim.n_frames), (int(stim.height), int(stim.width)),
                           stim.frames, stimulus=stim, label=stimulus_label(name, params))
