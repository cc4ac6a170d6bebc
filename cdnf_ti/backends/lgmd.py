"""The compiled backends of the LGMD family (LGMD2, LGMD1, F-LGMD ONn), driven by :mod:`cdnf_ti.kernels.lgmd`.

Per model a generic backend (``Taichi*Backend``: (H, W) arrays, GPUs and narrow
frames) and a lane backend (``LaneTaichi*Backend``: the fast CPU path).
"""
from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ..kernels import common
from ..kernels.common import MAX_STEPS, LaunchRecord
from ..kernels.schedule import MAX_WORKERS
from ..models.lgmd2 import lowpass_coefficient
from ..solver import RESTART_GROWTH
from ..taichi_runtime import cpu_threads, dsl, ensure_taichi, kernels, lanes
from .events import load_net_contrast
from .workspace import LaneState


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
        self.K = kernels("lgmd")
        self.params = params
        self.shape = tuple(shape)
        self.blocks = common.column_blocks(self.shape[1], arch)  # work items per row
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

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> float:
        """Take an event bin (H, W each, contrast in [0, 1]) as the net change ``P = 255 (p_on - p_off)``
        grey levels; returns what :meth:`load` returns (``sum |P|``)."""
        return load_net_contrast(self, p_on, p_off)

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


class LGMDLanes(LaneState):
    """The lane fields of an LGMD-family model for one frame size (:class:`LaneTaichiLGMDBackend`).

    Every layer in :attr:`LAYERS` is a lane array (a vector ndarray, ``LANES`` float32 per element,
    shape (H, NB); :func:`~cdnf_ti.kernels.common.lane_array`) in the lane
    layout of :mod:`cdnf_ti.kernels.common`; the channels ``on``/``off`` have
    :attr:`CHANNEL_BUFFERS` buffers (leading index). Each backend has its own (each model its own
    subclass, naming its layers); the scratch is the process's (:class:`~cdnf_ti.backends.workspace.Scratch`).
    """

    LAYERS: ClassVar[tuple[str, ...]] = ("L", "P", "on", "off")
    CHANNEL_BUFFERS: ClassVar[int] = 2

    def __init__(self, shape: tuple[int, int]):
        super().__init__(shape)
        C = kernels("common")
        lane_array, lane_layout = C.lane_array, C.lane_layout
        H, W = shape
        _, nb = lane_layout(W)
        for name in self.LAYERS:
            lead = (self.CHANNEL_BUFFERS,) if name in ("on", "off") else ()
            setattr(self, name, lane_array(*lead, H=H, NB=nb))


class LaneTaichiLGMDBackend:
    """The fast CPU backend of an LGMD-family model: its layers in lane arrays, kernels compiled with
    explicit vector types (:func:`~cdnf_ti.taichi_runtime.vector_kernel`).

    Same interface, equations and results as the model's ndarray backend
    (:class:`TaichiLGMDBackend`); the kernels are the ``lanes_*`` ones of
    :mod:`cdnf_ti.kernels.lgmd`. Each backend owns its fields (:attr:`workspace_type`).

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
        return arch == "cpu" and shape[1] >= 2 * lanes() and shape[0] >= 2

    def __init__(self, params: Any, shape: tuple[int, int], dt: int, arch: str = "cpu"):
        ensure_taichi(arch)
        self.K = kernels("lgmd")
        self.params = params
        self.shape = tuple(shape)
        self.W = int(shape[1])
        self.dt = dt
        self.nw = min(cpu_threads(), MAX_WORKERS)  # persistent workers per launch
        self.ws = self.workspace_type(self.shape)  # this backend's own arrays
        self.lock = self.ws.lock  # the process's scratch: held by the model around each frame (Model.step)
        self._load_out = np.zeros(1)  # lgmd_lanes_load's sum |P|
        self._setup()
        with self.lock:
            self.reset()

    def _setup(self) -> None:
        """The model's constants."""

    def _acquire(self) -> LGMDLanes:
        """This backend's arrays."""
        return self.ws

    # -- backend interface ---------------------------------------------------
    def reset(self) -> None:
        ws = self._acquire()
        for name in ws.LAYERS:
            getattr(ws, name).fill(0.0)
        self._reset_buffers()

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> float:
        """Take an event bin (H, W each, contrast in [0, 1]) as the net change ``P = 255 (p_on - p_off)``
        grey levels; returns what :meth:`load` returns (``sum |P|``)."""
        return load_net_contrast(self, p_on, p_off)

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


class TaichiLGMD1Backend(TaichiLGMDBackend):
    """LGMD1 layers in Taichi (see :class:`LGMD1`)."""

    LAYERS = ("I_on", "E_off", "S", "G")

    def _setup(self) -> None:
        p, dt = self.params, self.dt
        self.a = tuple(lowpass_coefficient(dt, t) for t in p.tau_lateral)
        self._layers_out = np.zeros(1)  # lgmd1_layers' sum G

    def layers(self) -> float:
        """Delayed spreads, S (thresholded), G (ON/OFF from :meth:`load`); returns ``sum G``."""
        p = self.params
        c, q = self._next_buffers()
        out = self._layers_out
        out.fill(0.0)
        self.K.lgmd1_layers(self.on[c], self.off[c], self.on[q], self.off[q], self.I_on, self.E_off,
                            self.S, self.G, p.w_i_on, p.w_i_off, *p.k_lateral, *self.a,
                            p.w_on_exc, p.w_off_exc, p.w_onoff, p.t_s, self.blocks, out)
        return float(out[0])


class _LGMD1Lanes(LGMDLanes):
    LAYERS = ("L", "P", "on", "off", "I_on", "E_off", "S", "G")


class LaneTaichiLGMD1Backend(PingPongLaneLGMDBackend):
    """LGMD1 layers on lane fields (see :class:`LGMD1`): a frame's layers in one launch."""

    workspace_type = _LGMD1Lanes
    FIELD_LAYERS = ("I_on", "E_off", "S", "G")

    def _setup(self) -> None:
        p, dt = self.params, self.dt
        self.a = tuple(lowpass_coefficient(dt, t) for t in p.tau_lateral)
        self._layers_out = np.zeros(1)  # lgmd1_lanes_layers' sum G

    def layers(self) -> float:
        """Delayed spreads, S (thresholded), G (ON/OFF from :meth:`load`); returns ``sum G``."""
        ws = self._acquire()
        p = self.params
        c, q = self._next_buffers()
        out = self._layers_out
        out.fill(0.0)
        self.K.lgmd1_lanes_layers(ws.on, ws.off, c, q, ws.I_on, ws.E_off, ws.S, ws.G, p.w_i_on, p.w_i_off,
                                  *p.k_lateral, *self.a, p.w_on_exc, p.w_off_exc, p.w_onoff, p.t_s, self.nw,
                                  ws.sync, ws.rbuf, ws.msum, self.W, out)
        return float(out[0])


class TaichiFLGMDBackend(TaichiLGMDBackend):
    """F-LGMD layers in Taichi (see :class:`FLGMDONn`): feedback iteration on the ON/OFF channels.

    Per frame: :meth:`load` writes the drives ``ON0``/``OFF0``; :meth:`prepare` the
    constant inhibition ``Q`` of both channels and the iterate's start;
    :meth:`feedback_iterate` one relaxed update; :meth:`finish` the layers at the
    fixed point.
    """

    LAYERS = ("S_on", "S_off", "S", "G")
    #: Current, previous (settled) and scratch buffers per channel.
    CHANNEL_BUFFERS = 3

    def _setup(self) -> None:
        p, dt = self.params, self.dt
        self.on0, self.off0 = self._nd(), self._nd()
        self.q_on, self.q_off = self._nd(), self._nd()
        self.a = tuple(lowpass_coefficient(dt, t) for t in p.tau_lateral)
        self.w_on, self.w_off = p.feedback_stencils(dt)
        start_on, start_off = p.local_start_gains(dt)
        self.start_gains = (*start_on, *start_off)  # w, kappa of ON, then of OFF
        self._iterate_out = np.zeros(2)  # flgmd_iterate's residuals of ON, OFF
        self._finish_out = np.zeros(1)  # flgmd_finish's sum G

    def reset(self) -> None:
        super().reset()
        self.pi = 1  # index of the previous (settled) buffers
        self.ni = 2  # scratch buffers

    def _channel_targets(self) -> tuple[Any, Any, Any, Any]:
        """The drives ``ON0``/``OFF0`` from the settled channels ``on[c]``/``off[c]``."""
        return self.on0, self.off0, self.on[self.c], self.off[self.c]

    def prepare(self) -> None:
        # the settled current buffers become the previous ones
        self.pi, self.c = self.c, self.pi
        p = self.params
        self.K.flgmd_prepare(self.on0, self.off0, self.on[self.c], self.off[self.c], self.on[self.pi],
                             self.off[self.pi], self.q_on, self.q_off, *p.k_lateral, *self.a,
                             p.w_i_on, p.w_i_off, *self.start_gains, self.blocks)

    def feedback_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        """One update ``X <- X + mom (X - X_prev) + lam (T(X) - X)``; returns the residuals before it."""
        p = self.params
        c, n = self.c, self.ni
        with_off = p.beta_off != 0.0
        out = self._iterate_out
        out.fill(0.0)
        self.K.flgmd_iterate(self.on0, self.off0, self.on[c], self.off[c], self.q_on, self.q_off,
                             self.on[n], self.off[n], *self.w_on, *self.w_off,
                             p.beta_on, p.beta_off, lam, mom, self.blocks, with_off, out)
        if with_off:
            self.c, self.ni = n, c
        else:
            # only ON was iterated: swap the ON buffers, keep OFF in place
            self.on[c], self.on[n] = self.on[n], self.on[c]
        return float(out[0]), float(out[1])

    def finish(self) -> float:
        p = self.params
        c = self.c
        out = self._finish_out
        out.fill(0.0)
        self.K.flgmd_finish(self.on[c], self.off[c], self.q_on, self.q_off, self.S_on, self.S_off,
                            self.S, self.G, *self.w_on, *self.w_off, p.t_s, self.blocks, out)
        return float(out[0])

    def hold(self) -> None:
        """FFI-held frame: the channels keep their previous values (nothing to do)."""


class _FLGMDLanes(LGMDLanes):
    LAYERS = ("L", "P", "on", "off", "on0", "off0", "q_on", "q_off", "S_on", "S_off", "S", "G")
    #: the settled channel of the last frame and two buffers for the iteration
    CHANNEL_BUFFERS = 3


class LaneTaichiFLGMDBackend(LaneTaichiLGMDBackend):
    """The fast F-LGMD backend on the CPU: the layers in lane arrays (float32 vector ndarrays).

    Same interface, equations, iteration schedule and residuals as
    :class:`TaichiFLGMDBackend`; the kernels are :func:`~cdnf_ti.kernels.lgmd.lgmd_lanes_load`
    (with the frame's constant inhibition ``Q`` and the iterate's start, so :meth:`prepare`
    only picks buffers) and ``flgmd_lanes_*``. A whole solve runs in one launch
    (:meth:`feedback_iterate_many`), which also computes the layers when it converges.
    """

    workspace_type = _FLGMDLanes
    FIELD_LAYERS = TaichiFLGMDBackend.LAYERS

    def _setup(self) -> None:
        p, dt = self.params, self.dt
        self.steps = MAX_STEPS  # updates per solve launch (feedback_iterate_many)
        self._tol32 = float(np.float32(p.tol))
        self._sum_g: float | None = None  # sum G computed by a converged solve launch
        self._record = LaunchRecord(2)  # flgmd_lanes_solve's coefficients in, residuals out
        self._solve_out = np.zeros(1)  # flgmd_lanes_solve's sum G (-1: not converged)
        self._finish_out = np.zeros(1)  # flgmd_lanes_finish's sum G
        a = tuple(lowpass_coefficient(dt, t) for t in p.tau_lateral)
        # edge and diagonal weights of Q = w_i sum K (1 - a) X(t-1), per channel
        self.q_weights = tuple(w * k * (1.0 - x) for w in (p.w_i_on, p.w_i_off) for k, x in zip(p.k_lateral, a))
        self.w_on, self.w_off = p.feedback_stencils(dt)
        start_on, start_off = p.local_start_gains(dt)
        self.start_gains = (*start_on, *start_off)  # w, kappa of ON, then of OFF

    def _reset_buffers(self) -> None:
        self.settled = [0, 0]  # buffer of the settled ON, OFF channel
        self.iterate = [1, 1]  # buffer of the current iterate of ON, OFF

    def load(self, grey: np.ndarray, first: bool) -> float:
        """Photoreceptors, drives, constant inhibition and the iterate's start; returns ``sum |P|``."""
        ws = self._acquire()
        self.iterate = [(c + 1) % 3 for c in self.settled]
        self._sum_g = None
        return self._load(grey, first, self.settled[0], self.iterate[0], self.settled[1], self.iterate[1],
                          (ws.on0, ws.off0, ws.q_on, ws.q_off, *self.q_weights, *self.start_gains))

    def prepare(self) -> None:
        """Nothing to compute: :meth:`load` wrote ``Q`` and the iterate's start."""

    def feedback_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        """One update ``X <- X + mom (X - X_prev) + lam (T(X) - X)``; returns the residuals before it."""
        return self.feedback_iterate_many([(lam, mom)])[0]

    def feedback_iterate_many(self, coefs) -> list[tuple[float, float]]:
        """Several updates in one launch (``coefs``: ``(lam, mom)`` each, at most ``steps``); see the solver.

        A launch that converges also computes the layers at the fixed point (:meth:`finish`
        then only reads ``sum G``).
        """
        ws = self._acquire()
        p = self.params
        with_off = p.beta_off != 0.0
        cur = list(self.iterate)
        other = [3 - self.settled[k] - cur[k] for k in range(2)]  # the third buffer: the iterate before
        rec, out = self._record, self._solve_out
        self.K.flgmd_lanes_solve(ws.on0, ws.off0, ws.on, ws.off, ws.q_on, ws.q_off, ws.S_on, ws.S_off, ws.S, ws.G,
                                 cur[0], other[0], cur[1], other[1], *self.w_on, *self.w_off, p.beta_on,
                                 p.beta_off, p.t_s, rec.start(coefs), len(coefs), self._tol32, RESTART_GROWTH,
                                 self.nw, ws.sync, ws.rbuf, ws.msum, self.W, with_off, out)
        res = rec.residuals(len(coefs))
        if len(res) % 2:
            self.iterate = [other[0], other[1] if with_off else cur[1]]
        self._sum_g = float(out[0]) if out[0] >= 0.0 else None
        return res

    def finish(self) -> float:
        """The layers at the fixed point; returns ``sum G`` (already computed by a converged launch)."""
        self.settled = list(self.iterate)
        if self._sum_g is not None:
            return self._sum_g
        ws = self._acquire()
        p = self.params
        out = self._finish_out
        out.fill(0.0)
        self.K.flgmd_lanes_finish(ws.on, ws.off, *self.settled, ws.q_on, ws.q_off, ws.S_on, ws.S_off,
                                  ws.S, ws.G, *self.w_on, *self.w_off, p.t_s, self.W, out)
        return float(out[0])

    def hold(self) -> None:
        """FFI-held frame: the channels keep their previous values (nothing to do)."""

    def _channel_buffers(self) -> tuple[int, int]:
        return self.settled[0], self.settled[1]


#: The family's backends by model name: (generic, lane).
FAMILY: dict[str, tuple[type, type]] = {
    "lgmd2": (TaichiLGMD2Backend, LaneTaichiLGMD2Backend),
    "lgmd1": (TaichiLGMD1Backend, LaneTaichiLGMD1Backend),
    "flgmd_onn": (TaichiFLGMDBackend, LaneTaichiFLGMDBackend),
}


def make_backend(model, shape: tuple[int, int], arch: str) -> Any:
    """The backend of an LGMD-family model: the lane one where it applies (and ``model.fast``)."""
    generic, lane = FAMILY[model.name]
    if model.fast and lane.supports(shape, arch):
        return lane(model.params, shape, model.dt, model.arch)
    return generic(model.params, shape, model.dt, model.arch)
