"""LGMD2 (Fu, Hu, Peng, Rind, Yue, IEEE Trans. Cybernetics 50(12):5074-5088, 2020).

Equations and defaults: ``shared/spec/BASELINES.md``, gathered from the
authors' public C# supplement (``lgmd2OpenSource.cs``). Per frame, with
``dt = 1000 // fps`` ms (integer: 33 at 30 fps) and grey levels in 0..255:

1. ``P = L(t) - L(t-1)``; ``PM(t) = a PM_raw + (1 - a) PM(t-1)``,
   ``PM_raw = mean |P|``, ``a = dt / (dt + tau_PM)``;
   ``w_on = max(PM / T_pm, 1)``, ``w_off = max(PM / T_pm, 0.5)``.
2. ``ON = P [P >= 0.1] + 0.1 ON(t-1)``; ``OFF = |P| [P < 0.1] + 0.1 OFF(t-1)``.
3. ``I(x, y) = sum_ij K(i, j) [a_ij X(x+i, y+j, t) + (1 - a_ij) X(x+i, y+j, t-1)]``,
   ``a_ij = dt / (dt + tau_ij)``, centre included.
4. ``S = S_on + S_off + S_on S_off``, ``S_on = [ON - w_on I_on]+``, ``S_off = [OFF - w_off I_off]+``.
5. ``Ce = S (*) ones/9``; ``omega = 0.01 + max|Ce| / 4``; ``G = S Ce / omega``, 0 unless ``0.5 G >= 15``.
6. ``K = 1 / (1 + exp(-sum G / N))``.
7. SFA: ``Kh = a_s (Kh(t-1) + K - K(t-1))`` if ``K - K(t-1) <= 0.003`` else ``a_s K``,
   ``a_s = tau_s / (tau_s + dt)``; ``Kh = max(Kh, 0.5)``.
8. ``n(t) = floor(exp(4 (Kh - 0.78)))``; the count adds ``n`` and resets to 0 on
   any frame with ``n = 0``; collision alert while the count ``>= 8``.

Frame 0 only initialises ``L``: the state stays at zero (as the C# code's
first call sees zeros for every previous value), the output is ``K = 0.5``.

This module also holds what the LGMD family shares: the scalar recurrences
(:func:`lowpass_coefficient`, :func:`sfa_step`, :func:`spike_count`) and the
base class :class:`LGMDFamily` that runs them identically for both backends.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Sequence

import numpy as np

from ..baselines_reference import NumpyLGMD2Backend
from ..params import ModelParams, check_params, sigmoid
from ..taichi_runtime import cpu_threads, dsl, ensure_taichi
from .base import Model, SharedWorkspace, StepResult, Trace
from .registry import register_model


def frame_interval_ms(fps: float) -> int:
    """``dt = 1000 // fps`` in integer ms (33 at 30 fps), as the authors' code."""
    dt = int(1000 // fps)
    if dt < 1:
        raise ValueError(f"fps {fps} gives a frame interval below 1 ms")
    return dt


def lowpass_coefficient(dt: int, tau: float) -> float:
    """``a = dt / (dt + tau)`` of a first-order low-pass (dt, tau in ms)."""
    return dt / (dt + tau)


def sfa_step(kh_prev: float, k_prev: float, k: float, threshold: float, a_s: float, floor: float = 0.5) -> float:
    """Spike frequency adaptation of the membrane potential.

    Parameters
    ----------
    kh_prev, k_prev, k : float
        ``Kh(t-1)``, ``K(t-1)`` and ``K(t)``.
    threshold : float
        ``T_sfa``: below or at this rise of K the adaptation accumulates.
    a_s : float
        ``tau_s / (tau_s + dt)``.
    floor : float
        Lower bound of the result (0.5).

    Returns
    -------
    float
        ``Kh(t)``.
    """
    d = k - k_prev
    kh = a_s * (kh_prev + d) if d <= threshold else a_s * k
    return max(kh, floor)


def spike_count(kh: float, t_sp: float, c_sp: float) -> int:
    """``n(t) = floor(exp(c_sp (Kh - t_sp)))`` spikes in this frame."""
    return int(math.floor(math.exp(c_sp * (kh - t_sp))))


@dataclass(frozen=True)
class LGMD2Params(ModelParams):
    """LGMD2 parameters (defaults: BASELINES.md / the authors' C# supplement).

    Attributes
    ----------
    tau_pm : float
        Time constant of the PM pathway (ms, 90).
    t_pm : float
        PM threshold of the adaptive inhibition biases (grey levels, 8).
    w_on_base, w_off_base : float
        Lower bounds of the ON/OFF inhibition biases (1 and 0.5).
    clip : float
        Clip point of the ON/OFF rectifiers (grey levels, 0.1).
    dc : float
        Residue of the previous ON/OFF value (0.1).
    k_on, k_off : (centre, edge, diagonal)
        3x3 inhibition kernels ((2, 0.5, 0.25) and (1, 0.25, 0.125)).
    tau_on, tau_off : (centre, edge, diagonal)
        Delays of the inhibitions (ms, (15, 30, 45) and (60, 120, 180)).
    w_on_exc, w_off_exc, w_onoff : float
        Weights of ``S = w_on_exc S_on + w_off_exc S_off + w_onoff S_on S_off`` (1, 1, 1).
    delta_c, c_w : float
        ``omega = delta_c + max|Ce| / c_w`` (0.01, 4).
    c_de, t_de : float
        Grouping decay: G kept where ``c_de G >= t_de`` (0.5, 15).
    c_sig : float
        ``K = sigmoid(sum G / (N c_sig))`` (1).
    tau_sfa : float
        SFA time constant (ms, 800).
    t_sfa : float
        SFA threshold on the rise of K (0.003).
    kh_floor : float
        Lower bound of the SFA output (0.5).
    t_sp, c_sp : float
        Spiking ``n = floor(exp(c_sp (Kh - t_sp)))`` (0.78, 4).
    n_ts : int
        Collision alert while the spike count is at least this (8).
    """

    tau_pm: float = 90.0
    t_pm: float = 8.0
    w_on_base: float = 1.0
    w_off_base: float = 0.5
    clip: float = 0.1
    dc: float = 0.1
    k_on: tuple[float, float, float] = (2.0, 0.5, 0.25)
    tau_on: tuple[float, float, float] = (15.0, 30.0, 45.0)
    k_off: tuple[float, float, float] = (1.0, 0.25, 0.125)
    tau_off: tuple[float, float, float] = (60.0, 120.0, 180.0)
    w_on_exc: float = 1.0
    w_off_exc: float = 1.0
    w_onoff: float = 1.0
    delta_c: float = 0.01
    c_w: float = 4.0
    c_de: float = 0.5
    t_de: float = 15.0
    c_sig: float = 1.0
    tau_sfa: float = 800.0
    t_sfa: float = 0.003
    kh_floor: float = 0.5
    t_sp: float = 0.78
    c_sp: float = 4.0
    n_ts: int = 8

    def __post_init__(self) -> None:
        check_params("LGMD2Params", [
            (self.tau_pm >= 0, f"tau_pm must be >= 0 ms, got {self.tau_pm}"),
            (self.t_pm > 0, f"t_pm must be > 0, got {self.t_pm}"),
            (len(self.k_on) == 3 and len(self.k_off) == 3, "k_on/k_off must be (centre, edge, diagonal)"),
            (len(self.tau_on) == 3 and len(self.tau_off) == 3, "tau_on/tau_off must be (centre, edge, diagonal)"),
            (all(t >= 0 for t in (*self.tau_on, *self.tau_off)), "delays tau_on/tau_off must be >= 0 ms"),
            (0 <= self.dc < 1, f"dc must be in [0, 1), got {self.dc}"),
            (self.c_w > 0 and self.delta_c > 0, "c_w and delta_c must be > 0"),
            (self.c_sig > 0, f"c_sig must be > 0, got {self.c_sig}"),
            (self.tau_sfa > 0, f"tau_sfa must be > 0 ms, got {self.tau_sfa}"),
            (int(self.n_ts) == self.n_ts and self.n_ts >= 1, f"n_ts must be a positive integer, got {self.n_ts}"),
        ])


class TaichiLGMDBackend:
    """Layers of an LGMD-family model in Taichi ndarrays (float32), driven by :mod:`cdnf_ti.kernels.lgmd`.

    The family's shared part: photoreceptors ``L``/``P``, the ON/OFF channel
    buffers, ``load``, ``reset`` and ``fields``. Each model's subclass names its
    own layers (``LAYERS``), sets its constants (:meth:`_setup`) and runs its
    kernels.

    Parameters
    ----------
    params : LGMD2Params, LGMD1Params or FLGMDParams
    shape : (H, W)
    dt : int
        Frame interval (ms).
    arch : str
    """

    name = "taichi"
    #: The model's own layers besides ``P``, ``ON``, ``OFF`` (allocated here, listed by :meth:`fields`).
    LAYERS: tuple[str, ...] = ()
    #: Buffers per ON/OFF channel (current and previous frame).
    CHANNEL_BUFFERS = 2

    def __init__(self, params: Any, shape: tuple[int, int], dt: int, arch: str = "cpu"):
        arch = ensure_taichi(arch)  # the arch in use ("gpu" resolves to one)
        # lazy: kernels compile for the compiler/arch that ensure_taichi picks at run time
        from ..kernels import lgmd as K
        from ..kernels.common import column_blocks

        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.blocks = column_blocks(self.shape[1], arch)  # work items per row
        self.dt = dt
        self._arrays: list[Any] = []
        self._load_out = np.zeros(1)  # load_frame's sum |P|
        self.L, self.P = self._nd(), self._nd()
        self.on = [self._nd() for _ in range(self.CHANNEL_BUFFERS)]
        self.off = [self._nd() for _ in range(self.CHANNEL_BUFFERS)]
        for layer in self.LAYERS:
            setattr(self, layer, self._nd())
        self._setup()
        self.reset()

    def _nd(self) -> Any:
        """A new (H, W) float32 ndarray, zeroed by :meth:`reset`."""
        ti = dsl()  # taichi or quadrants, chosen at run time
        a = ti.ndarray(ti.f32, self.shape)
        self._arrays.append(a)
        return a

    def _setup(self) -> None:
        """The model's constants (delay coefficients, kernels) and extra buffers."""

    def reset(self) -> None:
        for a in self._arrays:
            self.K.fill(a, 0.0)
        self.c = 0  # index of the current ON/OFF buffers

    def load(self, grey: np.ndarray, first: bool) -> float:
        """Photoreceptors and this frame's ON/OFF channels (into :meth:`_channel_targets`); returns ``sum |P|``."""
        scale = 1.0 if grey.dtype == np.uint8 else 255.0
        p = self.params
        out = self._load_out
        out.fill(0.0)
        self.K.load_frame(grey, self.L, self.P, *self._channel_targets(), scale, int(first), p.clip, p.dc,
                          self.blocks, out)
        return float(out[0])

    def _channel_targets(self) -> tuple[Any, Any, Any, Any]:
        """``(ON, OFF, ON(t-1), OFF(t-1))`` buffers of :meth:`load`: the next ping-pong buffers,
        made current by :meth:`_next_buffers` when the layers run (an FFI-held frame keeps the old ones)."""
        c, n = self.c, 1 - self.c
        return self.on[n], self.off[n], self.on[c], self.off[c]

    def _next_buffers(self) -> tuple[int, int]:
        """Make the other ON/OFF buffers current: ``(current, previous)`` indices."""
        c, q = 1 - self.c, self.c  # new current, previous
        self.c = c
        return c, q

    def fields(self) -> dict[str, np.ndarray]:
        c = self.c
        out = {"P": self.P.to_numpy(), "ON": self.on[c].to_numpy(), "OFF": self.off[c].to_numpy()}
        for k in self.LAYERS:
            out[k] = getattr(self, k).to_numpy()
        return out


class TaichiLGMD2Backend(TaichiLGMDBackend):
    """LGMD2 layers in Taichi (see :class:`LGMD2`)."""

    LAYERS = ("I_on", "I_off", "S", "Ce", "G")

    def _setup(self) -> None:
        p, dt = self.params, self.dt
        self.an = tuple(lowpass_coefficient(dt, t) for t in p.tau_on)
        self.af = tuple(lowpass_coefficient(dt, t) for t in p.tau_off)
        self._layers_out = np.zeros(2)  # lgmd2_layers' sum G, max |Ce|

    def layers(self, w_on: float, w_off: float) -> tuple[float, float]:
        """Delayed inhibition, S, grouping (ON/OFF from :meth:`load`); returns ``(sum G, max |Ce|)``."""
        p = self.params
        c, q = self._next_buffers()
        out = self._layers_out
        out.fill(0.0)
        self.K.lgmd2_layers(self.on[c], self.off[c], self.on[q], self.off[q], self.I_on, self.I_off,
                            self.S, self.Ce, self.G, w_on, w_off,
                            *p.k_on, *self.an, *p.k_off, *self.af, p.w_on_exc, p.w_off_exc, p.w_onoff,
                            p.delta_c, p.c_w, p.c_de, p.t_de, self.blocks, out)
        return float(out[0]), float(out[1])


class LGMDLanes(SharedWorkspace):
    """The lane fields of an LGMD-family model for one frame size (:class:`LaneTaichiLGMDBackend`).

    Every layer in :attr:`LAYERS` is a lane array (a vector ndarray, ``LANES`` float32 per element,
    shape (H, NB); :func:`~cdnf_ti.kernels.common.lane_array`) in the lane
    layout of :mod:`cdnf_ti.kernels.common`; the channels ``on``/``off`` have
    :attr:`CHANNEL_BUFFERS` buffers (leading index). Each model has its own subclass, so its
    fields (and compiled kernels) are shared by the models of that kind and size only.
    """

    LAYERS: ClassVar[tuple[str, ...]] = ("L", "P", "on", "off")
    CHANNEL_BUFFERS: ClassVar[int] = 2

    def __init__(self, shape: tuple[int, int]):
        super().__init__(shape)
        from ..kernels.common import MAX_STEPS, lane_array, lane_layout, sync_size

        ti = dsl()
        H, W = shape
        _, nb = lane_layout(W)
        for name in self.LAYERS:
            lead = (self.CHANNEL_BUFFERS,) if name in ("on", "off") else ()
            setattr(self, name, lane_array(*lead, H=H, NB=nb))
        self.sync = ti.field(ti.i32, sync_size())  # phase counters of the persistent workers
        self.rbuf = ti.field(ti.f32, (MAX_STEPS, 2))  # per-phase maxima (residuals, max |Ce|)
        self.msum = ti.field(ti.f64, 2)  # a launch's float64 sum, and a flag


class LaneTaichiLGMDBackend:
    """The fast CPU backend of an LGMD-family model: its layers in lane arrays, kernels compiled with
    explicit vector types (:func:`~cdnf_ti.taichi_runtime.vector_kernel`).

    Same interface, equations and results as the model's ndarray backend
    (:class:`TaichiLGMDBackend`); the kernels are the ``lanes_*`` ones of
    :mod:`cdnf_ti.kernels.lgmd`. The fields are shared per model kind and frame size
    (:attr:`workspace_type`); a backend whose state was evicted by another one of
    the same kind and size gets it back from NumPy.

    Parameters
    ----------
    params : the model's parameters
    shape : (H, W)
    dt : int
        Frame interval (ms).
    arch : str
    """

    name = "taichi"
    workspace_type: ClassVar[type[LGMDLanes]]
    #: Layers listed by :meth:`fields` besides ``P``, ``ON``, ``OFF``.
    FIELD_LAYERS: ClassVar[tuple[str, ...]] = ()
    #: Work items per row of the load kernel (element blocks), so both CPU threads get rows.
    BLOCKS = 4

    @staticmethod
    def supports(shape: tuple[int, int], arch: str = "cpu") -> bool:
        """The CPU, frames at least ``2 * LANES`` wide and two rows high."""
        from ..kernels.common import LANES

        return arch == "cpu" and shape[1] >= 2 * LANES and shape[0] >= 2

    def __init__(self, params: Any, shape: tuple[int, int], dt: int, arch: str = "cpu"):
        ensure_taichi(arch)
        from ..kernels import lgmd as K

        self.K = K
        self.params = params
        self.shape = tuple(shape)
        self.W = int(shape[1])
        self.dt = dt
        self.nw = min(cpu_threads(), K.MAX_WORKERS)  # persistent workers per launch
        self.ws = self.workspace_type.get(self.shape)
        self.lock = self.ws.lock
        self._saved: dict[str, np.ndarray] | None = None
        self._load_out = np.zeros(1)  # lgmd_lanes_load's sum |P|
        self._setup()
        with self.lock:
            self.reset()

    def _setup(self) -> None:
        """The model's constants."""

    # -- workspace ownership -----------------------------------------------
    def _acquire(self) -> LGMDLanes:
        ws = self.ws
        if ws.take(self) and self._saved is not None:
            for name, x in self._saved.items():
                getattr(ws, name).from_numpy(x)
            self._saved = None
        return ws

    def _evict(self) -> None:
        ws = self.ws
        self._saved = {name: getattr(ws, name).to_numpy() for name in ws.LAYERS}
        ws.owner = None

    # -- backend interface ---------------------------------------------------
    def reset(self) -> None:
        ws = self._acquire()
        for name in ws.LAYERS:
            getattr(ws, name).fill(0.0)
        self._reset_buffers()

    def _reset_buffers(self) -> None:
        """Back to the first buffers of the channels."""

    def _load(self, grey: np.ndarray, first: bool, c_on: int, s_on: int, c_off: int, s_off: int,
              feedback: tuple = ()) -> float:
        """:func:`cdnf_ti.kernels.lgmd.lgmd_lanes_load`: channels ``s`` from ``c``; returns ``sum |P|``.

        ``feedback``: F-LGMD's ``(on0, off0, q_on, q_off, qn1, qn2, qf1, qf2, wn, kn, wf, kf)``, else empty.
        """
        ws = self._acquire()
        p = self.params
        scale = 1.0 if grey.dtype == np.uint8 else 255.0
        extra = feedback or (ws.P, ws.P, ws.P, ws.P) + (0.0,) * 8  # not read without feedback
        out = self._load_out
        out.fill(0.0)
        self.K.lgmd_lanes_load(grey, ws.L, ws.P, ws.on, ws.off, c_on, s_on, c_off, s_off, scale, int(first),
                               p.clip, p.dc, self.W, self.BLOCKS, bool(feedback), *extra, out)
        return float(out[0])

    def _channel_buffers(self) -> tuple[int, int]:
        """Buffers of the ON and OFF channels that :meth:`fields` shows."""
        raise NotImplementedError

    def fields(self) -> dict[str, np.ndarray]:
        ws = self._acquire()
        b_on, b_off = self._channel_buffers()
        out = {"P": ws.frame(ws.P.to_numpy()), "ON": ws.frame(ws.on.to_numpy()[b_on]),
               "OFF": ws.frame(ws.off.to_numpy()[b_off])}
        for name in self.FIELD_LAYERS:
            out[name] = ws.frame(getattr(ws, name).to_numpy())
        return out


class PingPongLaneLGMDBackend(LaneTaichiLGMDBackend):
    """A lane backend whose channels have two buffers: :meth:`load` writes the channels of the
    new frame into the other buffer, and the layers make it current (:meth:`_next_buffers`). A
    frame that FFI holds runs no layers, so its channels are dropped, as in the ndarray backend."""

    def _reset_buffers(self) -> None:
        self.c = 0  # the current ON/OFF buffers; load writes the other ones

    def load(self, grey: np.ndarray, first: bool) -> float:
        n = 1 - self.c
        return self._load(grey, first, self.c, n, self.c, n)

    def _next_buffers(self) -> tuple[int, int]:
        """Make the other ON/OFF buffers current: ``(current, previous)`` indices."""
        q, self.c = self.c, 1 - self.c
        return self.c, q

    def _channel_buffers(self) -> tuple[int, int]:
        return self.c, self.c


class _LGMD2Lanes(LGMDLanes):
    LAYERS = ("L", "P", "on", "off", "I_on", "I_off", "S", "Ce", "G")


class LaneTaichiLGMD2Backend(PingPongLaneLGMDBackend):
    """LGMD2 layers on lane fields (see :class:`LGMD2`): a frame's layers in one launch."""

    workspace_type = _LGMD2Lanes
    FIELD_LAYERS = ("I_on", "I_off", "S", "Ce", "G")

    def _setup(self) -> None:
        p, dt = self.params, self.dt
        self.an = tuple(lowpass_coefficient(dt, t) for t in p.tau_on)
        self.af = tuple(lowpass_coefficient(dt, t) for t in p.tau_off)
        self._layers_out = np.zeros(2)  # lgmd2_lanes_layers' sum G, max |Ce|

    def layers(self, w_on: float, w_off: float) -> tuple[float, float]:
        """Delayed inhibition, S, grouping (ON/OFF from :meth:`load`); returns ``(sum G, max |Ce|)``."""
        ws = self._acquire()
        p = self.params
        c, q = self._next_buffers()
        out = self._layers_out
        out.fill(0.0)
        self.K.lgmd2_lanes_layers(ws.on, ws.off, c, q, ws.I_on, ws.I_off, ws.S, ws.Ce, ws.G, w_on, w_off,
                                  *p.k_on, *self.an, *p.k_off, *self.af, p.w_on_exc, p.w_off_exc, p.w_onoff,
                                  p.delta_c, p.c_w, p.c_de, p.t_de, self.nw, ws.sync, ws.rbuf, ws.msum, self.W, out)
        return float(out[0]), float(out[1])


class LGMDFamily(Model):
    """Shared orchestration of the LGMD family (both backends).

    Subclasses supply their backends and equations (:class:`~cdnf_ti.models.base.Model`
    hooks); the family shares the frame interval ``dt``, the scalar state
    (PM/FFI, ``K``/``Kh`` history, spike count), the membrane/SFA step and the
    spike count. Inputs are grey levels 0..255 (uint8 as is; float in [0, 1]
    times 255). ``threshold`` is None: the alert is a spike count, not a level
    of ``K`` (``Kh``/``n`` are diagnostics).
    """

    output_name = "K"

    #: Threshold sweep (experiments): the spike count at which the alert fires.
    sweep_parameter = "n_ts (alert while spike count >= value)"
    sweep_values = tuple(float(v) for v in range(1, 21))

    @classmethod
    def sweep_default(cls) -> float:
        return float(cls.params_type().n_ts)

    @classmethod
    def sweep_alerts(cls, trace: Trace, values: Sequence[float]) -> list[np.ndarray]:
        """Alerts per frame at each count threshold, from the saved ``count`` diagnostic.

        The spike count does not depend on the threshold, so ``count >= n_ts``
        on the saved trace is exactly what a rerun with that ``n_ts`` gives.
        """
        count = np.asarray(trace.diagnostics["count"], dtype=np.float64)
        return [count >= v for v in values]

    #: The model's backends, each built as ``(params, shape, dt)`` (Taichi: and ``arch``).
    taichi_backend_type: ClassVar[type[TaichiLGMDBackend]]
    numpy_backend_type: ClassVar[type]

    def _setup(self) -> None:
        self.dt = frame_interval_ms(self.fps)

    #: The fast CPU backend (lane fields), used where it :meth:`~LaneTaichiLGMDBackend.supports`
    #: the frame; ``None``: the model has none.
    lane_backend_type: ClassVar[type[LaneTaichiLGMDBackend] | None] = None
    #: Use the fast backend where it applies; ``False``: the generic kernels (same equations).
    fast: bool = True

    def _taichi_backend(self, shape: tuple[int, int]) -> TaichiLGMDBackend | LaneTaichiLGMDBackend:
        arch = ensure_taichi(self.arch)
        lanes = self.lane_backend_type
        if self.fast and lanes is not None and lanes.supports(shape, arch):
            return lanes(self.params, shape, self.dt, self.arch)
        return self.taichi_backend_type(self.params, shape, self.dt, self.arch)

    def _numpy_backend(self, shape: tuple[int, int]) -> Any:
        return self.numpy_backend_type(self.params, shape, self.dt)

    def _reset_state(self) -> None:
        self.pm = 0.0  # PM (LGMD2) or FFI (LGMD1 family), grey levels
        self.k_prev = 0.0
        self.kh_prev = 0.0
        self.count = 0

    def _track_pm(self, sum_p: float, n_cells: int, tau: float) -> float:
        """``PM(t) = a mean|P| + (1 - a) PM(t-1)``, ``a = dt / (dt + tau)``: LGMD2's PM, LGMD1's FFI.

        Updates and returns ``self.pm`` (grey levels); ``sum_p`` is ``sum |P|`` over ``n_cells`` pixels.
        """
        a = lowpass_coefficient(self.dt, tau)
        self.pm = a * (sum_p / n_cells) + (1.0 - a) * self.pm
        return self.pm

    def _spikes(self, kh: float) -> tuple[int, bool]:
        p = self.params
        n = spike_count(kh, p.t_sp, p.c_sp)
        self.count = 0 if n == 0 else self.count + n
        return n, self.count >= p.n_ts

    def _membrane(self, sum_g: float, n_cells: int) -> tuple[float, float]:
        """``K = sigmoid(sum G / (N c_sig))`` and its SFA-adapted ``Kh``; updates the history."""
        p = self.params
        k = sigmoid(sum_g / (n_cells * p.c_sig))
        a_s = p.tau_sfa / (p.tau_sfa + self.dt)
        kh = sfa_step(self.kh_prev, self.k_prev, k, p.t_sfa, a_s, p.kh_floor)
        self.k_prev, self.kh_prev = k, kh
        return k, kh


@register_model
class LGMD2(LGMDFamily):
    """LGMD2 collision-perception network (Fu et al. 2020), selective to darker looming objects.

    Parameters
    ----------
    params : LGMD2Params, optional
    backend : {"taichi", "numpy"}
        Taichi kernels (float32 layers) or the NumPy float64 reference.
    arch : str
        Taichi architecture.
    fps : float
        Input frame rate; ``dt = 1000 // fps`` ms.

    Notes
    -----
    ``output`` is ``K`` (sigmoid membrane potential); ``spike`` is the
    collision alert (spike count >= 8). Diagnostics per frame: ``Kh``
    (after SFA), ``n`` (spikes), ``count``, ``PM``, ``w_on``, ``w_off``,
    ``sum_G``, ``max_Ce``. :meth:`fields`: ``P, ON, OFF, I_on, I_off, S, Ce, G``.
    """

    name = "lgmd2"
    params_type = LGMD2Params
    description = "LGMD2 (Fu et al. 2020): biased ON/OFF, adaptive inhibition, SFA; equations from the authors' code"

    taichi_backend_type = TaichiLGMD2Backend
    lane_backend_type = LaneTaichiLGMD2Backend
    numpy_backend_type = NumpyLGMD2Backend

    def _step(self, t: int, grey: np.ndarray, sum_p: float) -> StepResult:
        p = self.params
        be = self._be
        if t == 0:
            return StepResult(t, 0.5, False, True, dict(Kh=p.kh_floor, n=0, count=0, PM=0.0,
                                                        w_on=p.w_on_base, w_off=p.w_off_base,
                                                        sum_G=0.0, max_Ce=0.0))
        n_cells = grey.shape[0] * grey.shape[1]
        self._track_pm(sum_p, n_cells, p.tau_pm)
        w_on = max(self.pm / p.t_pm, p.w_on_base)
        w_off = max(self.pm / p.t_pm, p.w_off_base)
        sum_g, max_ce = be.layers(w_on, w_off)
        k, kh = self._membrane(sum_g, n_cells)
        n, alert = self._spikes(kh)
        diag = dict(Kh=kh, n=n, count=self.count, PM=self.pm, w_on=w_on, w_off=w_off,
                    sum_G=sum_g, max_Ce=max_ce)
        return StepResult(t, k, alert, True, diag)
