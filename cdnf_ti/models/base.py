"""The interface every looming model implements, and the skeleton that runs it.

:class:`Model` owns the per-frame skeleton (backend creation, frame
preparation and size check, ``step``/``reset``/``fields``/``run``); a model
supplies its equations and state through hooks. :class:`ModelBackend` and
:class:`Sweepable` are the backend and threshold-sweep contracts, written as
:class:`typing.Protocol`.
"""
from __future__ import annotations

import contextlib
import csv
import io
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Iterable, Protocol, Sequence, runtime_checkable

import numpy as np
from tqdm import tqdm

from ..alert_rule import AlertRule
from ..atomic import atomic_write_text
from ..errors import UserError
from ..events.binning import DEFAULT_BIN_MS
from ..frames import ColourFrame, to_grey


class NotConvergedWarning(RuntimeWarning):
    """A per-frame fixed point did not reach its tolerance within ``max_iter``."""




@dataclass
class StepResult:
    """Output of one model step (one frame).

    Attributes
    ----------
    t : int
        Frame index (0-based) within the current run.
    output : float
        The model's continuous output (C-DNF: ``I_v``; LGMD family: ``K``).
    spike : bool
        Collision alert on this frame.
    converged : bool
        Every iterative solve of this frame reached its tolerance (always True
        for models without per-frame iteration).
    diagnostics : dict of str to float
        Model-specific per-frame values (iterations, residuals, ...).
    """

    t: int
    output: float
    spike: bool
    converged: bool = True
    diagnostics: dict[str, float] = field(default_factory=dict)


@dataclass
class Trace:
    """Per-frame results of a model over a frame stream (arrays over frames).

    Attributes
    ----------
    model : str
        Registry name of the model.
    output_name : str
        Name of the continuous output (``"I_v"`` for C-DNF).
    threshold : float or None
        The alert threshold on ``output`` when the model has one (for plots).
    output, spike, converged : ndarray, shape (T,)
    diagnostics : dict of str to ndarray, shape (T,)
    seconds : float
        Wall time spent in the model's timed steps (s), excluding frame decoding: every step
        but the set-up steps (:attr:`compile_seconds`).
    compile_seconds : float
        Wall time of the set-up steps (s): the first step, which builds the model's backend, and
        every step during which a kernel compiled (or loaded from the compile cache), whenever it
        happened (oLGMD compiles its layers on its first active frame, index 2).
    timed_frames : int or None
        Steps timed in :attr:`seconds` (None: not measured, e.g. a trace read from CSV).
    """

    model: str
    output_name: str
    threshold: float | None
    output: np.ndarray
    spike: np.ndarray
    converged: np.ndarray
    diagnostics: dict[str, np.ndarray]
    seconds: float = 0.0
    compile_seconds: float = 0.0
    timed_frames: int | None = None

    @property
    def n_frames(self) -> int:
        return int(self.output.shape[0])

    @property
    def first_alert(self) -> int | None:
        """Index of the first frame with a spike, or ``None``."""
        idx = np.flatnonzero(self.spike)
        return int(idx[0]) if idx.size else None

    @property
    def fps(self) -> float:
        """Model throughput in frames per second: :attr:`timed_frames` / :attr:`seconds` (nan when none was timed)."""
        timed = self.timed_frames or 0
        return timed / self.seconds if self.seconds > 0 and timed > 0 else float("nan")

    @classmethod
    def from_steps(cls, model: "Model", steps: list[StepResult], seconds: float, compile_seconds: float = 0.0,
                   timed_frames: int | None = None) -> "Trace":
        keys: list[str] = []
        for s in steps:
            for k in s.diagnostics:
                if k not in keys:
                    keys.append(k)
        diag = {k: np.array([s.diagnostics.get(k, np.nan) for s in steps], dtype=np.float64) for k in keys}
        return cls(
            model=model.name,
            output_name=model.output_name,
            threshold=model.threshold,
            output=np.array([s.output for s in steps], dtype=np.float64),
            spike=np.array([s.spike for s in steps], dtype=bool),
            converged=np.array([s.converged for s in steps], dtype=bool),
            diagnostics=diag,
            seconds=seconds,
            compile_seconds=compile_seconds,
            timed_frames=timed_frames,
        )

    def to_csv_text(self) -> str:
        """CSV text: ``frame, <output_name>, spike, converged, <diagnostics...>``."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        keys = list(self.diagnostics)
        w.writerow(["frame", self.output_name, "spike", "converged", *keys])
        for t in range(self.n_frames):
            row: list[Any] = [t, f"{self.output[t]:.9f}", int(self.spike[t]), int(self.converged[t])]
            for k in keys:
                val = self.diagnostics[k][t]
                row.append(int(val) if float(val).is_integer() and abs(val) < 2**31 else f"{val:.6g}")
            w.writerow(row)
        return buf.getvalue()

    def to_csv(self, path) -> None:
        """Write :meth:`to_csv_text` atomically to ``path``."""
        atomic_write_text(path, self.to_csv_text())

    @classmethod
    def from_csv(cls, path, model: str = "", threshold: float | None = None) -> "Trace":
        """Read a trace written by :meth:`to_csv`."""
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
        header, body = rows[0], rows[1:]
        cols = {name: np.array([float(r[i]) for r in body]) for i, name in enumerate(header)}
        output_name = header[1]
        diag = {k: v for k, v in cols.items() if k not in ("frame", output_name, "spike", "converged")}
        return cls(model, output_name, threshold, cols[output_name], cols["spike"].astype(bool),
                   cols["converged"].astype(bool), diag)


@runtime_checkable
class ModelBackend(Protocol):
    """What a model's execution backend provides: the per-pixel state for one frame size.

    A model builds its backend at the first frame (:meth:`Model._taichi_backend`
    or :meth:`Model._numpy_backend`). Beyond these members, the backends of one
    model share its own stage methods (e.g. C-DNF's ``contrast_iterate``), which
    only that model's :meth:`Model._step` calls.

    Attributes
    ----------
    name : str
        ``"taichi"`` or ``"numpy"``.
    shape : (H, W)
        Frame size in pixels.
    """

    name: str
    shape: tuple[int, ...]

    def load(self, grey: np.ndarray, first: bool) -> Any:
        """Take the next frame (H, W; uint8 or float in [0, 1]); ``first``: no previous frame.

        Returns what the model's equations need from the input stage
        (e.g. ``sum |P|``), or None.
        """

    def reset(self) -> None:
        """Return to the state before the first frame."""

    def fields(self) -> dict[str, np.ndarray]:
        """The inner layers, (H, W) each."""

    # Optional: ``expect_frames(dtype)``, told the first frame's dtype before the model's
    # ``_init_backend`` (C-DNF's lane backend compiles its frame kernel for that type only).


@runtime_checkable
class Sweepable(Protocol):
    """The threshold-sweep contract of :mod:`cdnf_ti.experiments.sweep`.

    A model class whose alert rule can be replayed on a saved :class:`Trace` at
    other threshold values (no re-run) provides these. :class:`Model` gives
    defaults for all but :meth:`sweep_alerts`, so a model is swept with its own
    rule exactly when it defines ``sweep_alerts``; otherwise the sweep
    thresholds its saved ``output``.

    Attributes
    ----------
    sweep_parameter : str
        Name of the swept quantity, as shown in reports (``"threshold"``).
    sweep_values : sequence of float or None
        The values swept (None: a data-driven range over the saved outputs).
    """

    sweep_parameter: str
    sweep_values: Sequence[float] | None

    @classmethod
    def sweep_default(cls) -> float | None:
        """The model's default value of the swept quantity (marked in plots), or None."""

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> Sequence[np.ndarray | int | None]:
        """Per value: a boolean spike array over frames, or the first-alert frame (None or -1: never)."""


class Model:
    """Base class of every looming-perception model in cdnf_ti.

    The base class runs the per-frame skeleton: backend creation at the first
    frame (Taichi or NumPy), frame preparation (grey conversion, frame-size
    check), loading the frame into the backend, frame counting, :meth:`reset`,
    :meth:`fields` and :meth:`run`. A model supplies only its equations and
    state through these hooks:

    * :meth:`_taichi_backend` / :meth:`_numpy_backend` (one for each name in
      ``BACKENDS``): build a :class:`ModelBackend` for frames of a given shape;
    * :meth:`_step` (required): the equations of one frame, given what the
      backend's ``load`` returned;
    * :meth:`_reset_state` (optional): reset the model's scalar state;
    * :meth:`_setup` (optional): derived constants, once at construction;
    * :meth:`_init_backend` (optional): prepare a new backend before its
      first frame (e.g. solve a resting state).

    :meth:`reset` resets the model's state and calls the backend's ``reset``.

    Subclasses set ``name`` (registry key), ``output_name`` and
    ``params_type``, and are registered with
    :func:`~cdnf_ti.models.registry.register_model` (a class decorator).
    A model that needs a different per-frame flow may override :meth:`step`,
    :meth:`reset` and :meth:`fields` instead.

    Parameters
    ----------
    params : dataclass instance, optional
        The model's parameters (defaults when omitted).
    backend : {"taichi", "numpy"}
        ``taichi`` runs the kernels; ``numpy`` the float64 reference.
    arch : str
        Taichi architecture (``cpu`` default; ``cuda``/``vulkan`` where available).
    fps : float
        Frame rate of the input (models with time constants need it).
    compiler : {"quadrants", "taichi"} or None
        Kernel compiler of the process (see :mod:`cdnf_ti.taichi_runtime`); ``None``: the
        one running, else the fastest installed.
    """

    name: ClassVar[str] = ""
    output_name: ClassVar[str] = "output"
    params_type: ClassVar[type] = object
    description: ClassVar[str] = ""
    #: Where ``--models all`` runs the model: by ``order``, then by name (C-DNF 0, Table I's models 1-4).
    order: ClassVar[int] = 100
    BACKENDS: ClassVar[tuple[str, ...]] = ("taichi", "numpy")
    #: The engine that compiles the kernels and builds a model's ``"taichi"`` backend
    #: (:class:`cdnf_ti.backends.Engine`: ``select_compiler(name)``, ``start(arch)``,
    #: ``backend(model, shape)``). Installed by the ``cdnf_ti`` package, so that models/
    #: states equations and control only and never imports the compiler.
    engine: ClassVar[Any] = None

    #: The model's kernel module (a module name under ``kernels/``, or a ``build(ti, lanes)`` function): its
    #: compiled backend is then the engine's one generic backend (``cdnf_ti.backends.engine``).
    kernels: ClassVar[Any] = None
    #: The fields ``render`` shows first: ``(field name, panel title)`` pairs.
    panels: ClassVar[tuple[tuple[str, str], ...]] = ()

    #: Threshold sweep (:class:`Sweepable`): defaults; a model opts in by defining ``sweep_alerts``.
    #: whether the model has an ON/OFF input stage for event bins (:meth:`step_on_off`)
    takes_events: ClassVar[bool] = False
    sweep_parameter: ClassVar[str] = "threshold"
    sweep_values: ClassVar[Sequence[float] | None] = None

    @classmethod
    def sweep_default(cls) -> float | None:
        """Default value of the swept quantity (None: unknown)."""
        return None

    @classmethod
    def event_bin_ms(cls, params: Any = None) -> float | None:
        """The bin width, ms, at which the model takes an event recording when ``--bin-ms`` is not given.

        A model whose equations have their own time step states it here (the event-based looming
        detector: its ``dt``, the bins its authors feed it), so that a recording reaches it at that
        step; :func:`bin_ms_for` resolves the width a run uses.

        Parameters
        ----------
        params : the model's parameter object, optional
            The parameters the model runs with (None: its defaults); the width may depend on them.

        Returns
        -------
        float or None
            Bin width in ms (> 0), or None (the default): no preference, the project's default
            width :data:`~cdnf_ti.events.binning.DEFAULT_BIN_MS` (1000/30 ms, one 30 fps frame).
        """
        return None

    @classmethod
    def frame_colour(cls, params: Any = None) -> str:
        """Which frames the model takes from the pipeline: ``"grey"`` (the default) or ``"bgr"``.

        ``"grey"``: the frame as :func:`~cdnf_ti.frames.to_grey` makes it, (H, W). ``"bgr"``: the frame as
        decoded, (H, W, 3) BGR uint8 where the input has colour, else the grey frame (a generated
        stimulus, a grey video, a rainy frame). The commands decode each frame once, make it grey
        once, and hand each model the form it names here (a :class:`~cdnf_ti.frames.ColourFrame`
        given to :meth:`step` is picked from by this).

        Parameters
        ----------
        params : the model's parameter object, optional
            The parameters the model runs with (None: its defaults); the choice may depend on them.

        Returns
        -------
        str
            ``"grey"`` or ``"bgr"``.
        """
        return "grey"

    def __init__(self, params: Any = None, *, backend: str = "taichi", arch: str = "cpu", fps: float = 30.0,
                 compiler: str | None = None):
        if backend not in self.BACKENDS:
            raise ValueError(f"{self.name}: unknown backend {backend!r}; choose one of {self.BACKENDS}")
        if not (fps > 0):
            raise ValueError(f"{self.name}: fps must be > 0, got {fps}")
        self.params = params if params is not None else self.params_type()
        if not isinstance(self.params, self.params_type):
            raise TypeError(f"{self.name}: params must be {self.params_type.__name__}")
        self.backend_name = backend
        self.arch = arch
        if backend == "taichi" and compiler is not None:
            self._engine().select_compiler(compiler)  # before the runtime starts
        self.compiler = compiler
        self.fps = float(fps)
        self._unconverged = 0
        self._be: ModelBackend | None = None
        self._t = 0
        if backend == "taichi":
            self._engine().start(arch)
        self._setup()
        self._reset_state()

    @property
    def threshold(self) -> float | None:
        """Alert threshold on the continuous output, if the model has one."""
        return None

    def alert_rule(self) -> AlertRule:
        """The model's alert rule with its parameters: the trace column it compares, the level and the
        rule in words (what ``run``'s line, summary.csv and ``live``'s ``start`` event report).

        Default: ``output > threshold`` when the model has a :attr:`threshold`, else the spike itself.
        A model whose alert compares something else (a count, a sum of frames) overrides it.
        """
        if self.threshold is not None:
            thr = float(self.threshold)
            return AlertRule(f"{self.output_name} > {thr:.4g}", self.output_name, self.output_name, thr, strict=True)
        return AlertRule("spike", "spike", "spike", 1.0)

    # -- the per-frame skeleton ------------------------------------------------
    def step(self, frame: np.ndarray) -> StepResult:
        """Process one frame (2-D grey float in [0, 1] or uint8, or BGR uint8; or a
        :class:`~cdnf_ti.frames.ColourFrame`, of which it takes the form :meth:`frame_colour` names).

        The frame is converted to grey, checked against the model's frame size
        (fixed by the first frame), loaded into the backend, and handed to the
        model's equations (:meth:`_step`). Kernels compiled meanwhile are announced (:meth:`_compiling`).
        """
        if isinstance(frame, ColourFrame):  # the pipeline's frame in both forms: the one this model takes
            frame = frame.bgr if self.frame_colour(self.params) == "bgr" else frame.grey
        with self._compiling(np.shape(frame)):
            return self._step_frame(frame)

    def _step_frame(self, frame: np.ndarray) -> StepResult:
        """:meth:`step` without the compile notice."""
        grey = self._prepare(frame)
        with self._backend_lock():
            t = self._t
            loaded = self._be.load(grey, t == 0)
            self._t += 1
            result = self._step(t, grey, loaded)
        if not result.converged:
            self._unconverged += 1
        return result

    def step_on_off(self, p_on: np.ndarray, p_off: np.ndarray) -> StepResult:
        """Process one bin of an event camera: the ON/OFF contrast ``p_on``, ``p_off`` (H, W), in [0, 1].

        The bin goes straight into the model's ON/OFF input stage (its backend's
        ``load_on_off``) instead of the photoreceptors' luminance change. Every bin
        is a full step, bin 0 included (an event bin needs no previous frame).

        Raises
        ------
        UserError
            The model has no ON/OFF input stage for events.
        """
        p_on = np.asarray(p_on)
        p_off = np.asarray(p_off)
        if p_on.ndim != 2 or p_on.shape != p_off.shape:
            raise ValueError(f"p_on and p_off must be (H, W) arrays of one shape, got {p_on.shape} and {p_off.shape}")
        if not self.takes_events:
            raise UserError(f"model {self.name} does not take event input yet")
        with self._compiling(p_on.shape):
            return self._step_bin(p_on, p_off)

    def _step_bin(self, p_on: np.ndarray, p_off: np.ndarray) -> StepResult:
        """:meth:`step_on_off` after its checks, without the compile notice."""
        if self._be is None:
            self._make_backend(p_on.shape, np.dtype(np.float32))
        elif p_on.shape != self._be.shape:
            raise ValueError(f"bin {self._t} is {p_on.shape[1]}x{p_on.shape[0]} but this model runs at "
                             f"{self._be.shape[1]}x{self._be.shape[0]}; call reset() on a new model")
        with self._backend_lock():
            t = self._t
            loaded = self._be.load_on_off(p_on, p_off, t == 0)
            self._t += 1
            result = self._step(t, None, loaded)
        if not result.converged:
            self._unconverged += 1
        return result

    def reset(self) -> None:
        """Forget all state; the next frame is treated as the first."""
        self._t = 0
        self._reset_state()
        if self._be is not None:
            with self._backend_lock():
                self._be.reset()

    def fields(self) -> dict[str, np.ndarray]:
        """Copies of the model's inner layers/fields, each (H, W), for pictures (empty before a frame)."""
        if self._be is None:
            return {}
        with self._backend_lock():
            return {k: np.asarray(v) for k, v in self._be.fields().items()}

    def _compiling(self, shape: Sequence[int]) -> Any:
        """The context of a step at frames of ``shape`` (H, W, ...): the engine announces kernels compiled in it
        ("compiling kernels for cdnf at 432x240, first time only; ..."); a no-op for the ``numpy`` backend."""
        scope = getattr(self.engine, "compiling", None) if self.backend_name == "taichi" else None
        if scope is None or len(shape) < 2:
            return contextlib.nullcontext()
        return scope(f"{self.name} at {shape[1]}x{shape[0]}")

    def _backend_lock(self) -> Any:
        """The lock of a backend whose buffers are shared with other models (else a no-op context)."""
        return getattr(self._be, "lock", None) or contextlib.nullcontext()

    def _prepare(self, frame: np.ndarray) -> np.ndarray:
        """Grey (H, W) frame; builds the backend at the first frame, then checks the size."""
        grey = to_grey(frame)
        if self._be is None:
            self._make_backend(grey.shape, grey.dtype)
        elif grey.shape != self._be.shape:
            raise ValueError(f"frame {self._t} is {grey.shape[1]}x{grey.shape[0]} but this model runs at "
                             f"{self._be.shape[1]}x{self._be.shape[0]}; call reset() on a new model")
        return grey

    def _make_backend(self, shape: tuple[int, int], dtype: np.dtype | None = None) -> ModelBackend:
        """Build the backend for frames of ``shape`` (H, W) and make it this model's.

        ``dtype``: the first frame's (uint8 or float); a backend with an ``expect_frames``
        method is told it before :meth:`_init_backend`, so it prepares (compiles) for those.
        """
        make = self._taichi_backend if self.backend_name == "taichi" else self._numpy_backend
        backend = make(tuple(shape))
        if dtype is not None and hasattr(backend, "expect_frames"):
            backend.expect_frames(np.dtype(dtype))
        with getattr(backend, "lock", None) or contextlib.nullcontext():
            self._init_backend(backend)
        self._be = backend
        return backend

    # -- hooks supplied by each model ---------------------------------------------
    def _taichi_backend(self, shape: tuple[int, int]) -> ModelBackend:
        """The compiled backend for frames of ``shape`` (H, W), from the engine (:attr:`engine`)."""
        return self._engine().backend(self, tuple(shape))

    def compile_count(self) -> int:
        """How many kernels the process has compiled (or loaded from the compile cache) so far: a step
        during which it grows compiled (:func:`run_models` leaves it out of the trace's time).

        The engine's count for the ``taichi`` backend; 0 for the ``numpy`` reference, which compiles nothing.
        """
        if self.backend_name != "taichi" or self.engine is None:
            return 0
        count = getattr(self.engine, "compile_count", None)
        return int(count()) if count is not None else 0

    @classmethod
    def _engine(cls) -> Any:
        """The engine that builds compiled backends (:attr:`engine`)."""
        if cls.engine is None:
            raise RuntimeError("no engine installed: import cdnf_ti (it installs cdnf_ti.backends.ENGINE)")
        return cls.engine

    def _numpy_backend(self, shape: tuple[int, int]) -> ModelBackend:
        """The NumPy float64 reference backend for frames of ``shape`` (H, W)."""
        raise NotImplementedError(f"{type(self).__name__} has no NumPy backend")

    def _step(self, t: int, grey: np.ndarray, loaded: Any) -> StepResult:
        """The model's equations for frame ``t`` (0-based).

        Parameters
        ----------
        t : int
            Frame index; ``t == 0`` is the first frame since :meth:`reset`.
        grey : ndarray, shape (H, W), or None
            The grey frame (already loaded into ``self._be``); ``None`` for an event bin
            (:meth:`step_on_off`), which is a full step even at ``t == 0``.
        loaded : Any
            What the backend's ``load`` returned for it.
        """
        raise NotImplementedError(f"{type(self).__name__} defines no equations (_step)")

    def _setup(self) -> None:
        """Derived constants from ``params`` and ``fps``, once at construction (default: none)."""

    def _reset_state(self) -> None:
        """Reset the model's own (scalar) state; called at construction and by :meth:`reset`."""

    def _init_backend(self, backend: ModelBackend) -> None:
        """Prepare a new backend before its first frame (default: nothing to do)."""

    def run(self, frames: Iterable[np.ndarray], progress: bool | str = False, total: int | None = None) -> Trace:
        """Reset, then step through ``frames`` and return the :class:`Trace`.

        Parameters
        ----------
        frames : iterable of ndarray
            Frame stream (consumed lazily; never held in memory at once).
        progress : bool or str
            Show a tqdm progress bar (a string is used as its label).
        total : int, optional
            Number of frames, for the progress bar.
        """
        return run_models([self], frames, progress=progress, total=total)[0]


def bin_ms_for(model: "type[Model] | Model", params: Any = None, bin_ms: float | None = None) -> float:
    """The bin width, ms, at which ``model`` (a class, or an instance: its parameters unless ``params``) takes
    an event recording.

    ``bin_ms`` (``--bin-ms``) when given, for every model; else the model's own
    (:meth:`Model.event_bin_ms`); else :data:`~cdnf_ti.events.binning.DEFAULT_BIN_MS`. Every command
    that bins a recording for a model (``run``, ``render``, the batch runs) asks here.
    """
    if bin_ms is not None:
        return float(bin_ms)
    if params is None and isinstance(model, Model):
        params = model.params
    own = model.event_bin_ms(params)
    return DEFAULT_BIN_MS if own is None else float(own)


def takes_colour(models: "Iterable[Model]") -> bool:
    """Whether any of ``models`` takes colour frames (:meth:`Model.frame_colour` ``"bgr"`` for its parameters):
    then a command decodes its frames as :class:`~cdnf_ti.frames.ColourFrame` (:func:`~cdnf_ti.frames.iter_frames`)."""
    return any(m.frame_colour(m.params) == "bgr" for m in models)


def run_models(models: "list[Model]", frames: Iterable[np.ndarray], progress: bool | str = False,
               total: int | None = None, errors: "list[BaseException | None] | None" = None,
               clock: Callable[[], float] = time.perf_counter) -> list[Trace]:
    """Reset several models and step them all through one pass over ``frames``.

    Each frame is decoded (and e.g. rain is generated) once and handed to every
    model in turn; each model's time is measured separately.

    Parameters
    ----------
    models : list of Model
    frames : iterable of ndarray, of ColourFrame or of (p_on, p_off)
        Frame stream (consumed lazily); a :class:`~cdnf_ti.frames.ColourFrame` gives each model the form
        it takes (:meth:`Model.frame_colour`); a tuple item is an event bin (:meth:`Model.step_on_off`).
    progress : bool or str
        Show a tqdm progress bar (a string is used as its label).
    total : int, optional
        Number of frames, for the progress bar.
    errors : list, optional
        Isolate the models from each other: an exception raised by one model's
        ``reset``/``step`` is stored at its index in this list (filled with None
        first), that model stops and its trace is None; the others go on. An
        error of the frame stream itself (a corrupt file) still raises.
    clock : callable
        Seconds from an arbitrary origin (default :func:`time.perf_counter`).

    Notes
    -----
    A model's set-up steps, its first (it builds the backend) and every step during which its
    :meth:`Model.compile_count` grew, are timed apart (:attr:`Trace.compile_seconds`), so
    :attr:`Trace.fps` is the speed of the steps that only compute, wherever the compiles fall.

    Returns
    -------
    list of Trace
        One per model, in order (None for a model that failed, with ``errors``).
    """
    if errors is not None:
        errors[:] = [None] * len(models)
    for k, m in enumerate(models):
        try:
            m.reset()
        except Exception as e:
            if errors is None:
                raise
            errors[k] = e
    steps: list[list[StepResult]] = [[] for _ in models]
    seconds = [0.0] * len(models)
    setup_seconds = [0.0] * len(models)
    timed = [0] * len(models)
    bar = None
    if progress:
        bar = tqdm(total=total, desc=progress if isinstance(progress, str) else models[0].name,
                   unit="frame", leave=False, disable=None)
    try:
        for frame in frames:
            for k, m in enumerate(models):
                if errors is not None and errors[k] is not None:
                    continue
                compiles = m.compile_count()
                t0 = clock()
                try:
                    steps[k].append(m.step_on_off(*frame) if isinstance(frame, tuple) else m.step(frame))
                except Exception as e:
                    if errors is None:
                        raise
                    errors[k] = e
                    continue
                took = clock() - t0
                if len(steps[k]) == 1 or m.compile_count() != compiles:  # built the backend or compiled
                    setup_seconds[k] += took
                else:
                    seconds[k] += took
                    timed[k] += 1
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    traces = []
    for k, m in enumerate(models):
        if errors is not None and errors[k] is not None:
            traces.append(None)
            continue
        trace = Trace.from_steps(m, steps[k], seconds[k], setup_seconds[k], timed[k])
        n_bad = int((~trace.converged).sum())
        if n_bad:
            warnings.warn(
                f"{m.name}: {n_bad} of {trace.n_frames} frames did not reach the tolerance "
                "(see the 'converged' column)",
                NotConvergedWarning,
                stacklevel=3,
            )
        traces.append(trace)
    return traces


