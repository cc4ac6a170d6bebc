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
from .workspace import LaneState, event_bin


def coefficient_array(K: Any, values: dict[int, Any]) -> np.ndarray:
    """A model's coefficients as the float32 array of the kernels (``K.N_COEFS`` long): ``values`` maps
    an index of :mod:`cdnf_ti.kernels.lgmd` (``K.CLIP``, ``K.KN``...) to a value, or to a sequence
    that fills consecutive entries from there; the rest are 0."""
    a = np.zeros(K.N_COEFS, np.float32)
    for k, v in values.items():
        v = np.atleast_1d(np.asarray(v, np.float64))
        a[k:k + len(v)] = v  # rounded to float32 as a float32 kernel argument would be
    return a


class StateLayout:
    """Where a model's layers and channel buffers sit in its state array (leading axis).

    Parameters
    ----------
    layers : tuple of str
        The model's layers (:data:`cdnf_ti.kernels.lgmd.STATE_LAYERS`), first in the array.
    buffers : int
        Buffers per ON/OFF channel, after the layers: ON's, then OFF's.
    """

    def __init__(self, layers: tuple[str, ...], buffers: int):
        self.index = {name: k for k, name in enumerate(layers)}
        self.on = [len(layers) + b for b in range(buffers)]  # ON's buffers
        self.off = [len(layers) + buffers + b for b in range(buffers)]  # OFF's buffers
        self.size = len(layers) + 2 * buffers


class TaichiLGMDBackend:
    """Layers of an LGMD-family model in one Taichi ndarray (float32, (layers, H, W)), driven by
    :mod:`cdnf_ti.kernels.lgmd`.

    The family's shared part: the state array ``st`` (photoreceptors ``L``/``P``, the model's
    layers, the ON/OFF channel buffers; :class:`StateLayout`), the coefficient array ``coef``
    (set once, :meth:`_coefficients`), ``load``, ``reset`` and ``fields``. Each model's subclass
    names its layers (``MODEL``, ``LAYERS``), sets its constants (:meth:`_setup`) and runs its kernels.

    Parameters
    ----------
    params : LGMD2Params, LGMD1Params or FLGMDParams
    shape : (H, W)
    dt : int
        Frame interval (ms).
    arch : str
    """

    name = "taichi"
    #: The model's key in :data:`cdnf_ti.kernels.lgmd.STATE_LAYERS`.
    MODEL: ClassVar[str]
    #: The model's own layers that :meth:`fields` lists besides ``P``, ``ON``, ``OFF``.
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
        self._load_out = np.zeros(1)  # load_frame's sum |P|
        self.layout = StateLayout(self.K.STATE_LAYERS[self.MODEL], self.CHANNEL_BUFFERS)
        self.on, self.off = list(self.layout.on), list(self.layout.off)  # the channels' buffers (indices)
        ti = dsl()  # taichi or quadrants, chosen at run time
        self.st = ti.ndarray(ti.f32, (self.layout.size, *self.shape))
        self._setup()
        self.coef = ti.ndarray(ti.f32, self.K.N_COEFS)
        self.coef.from_numpy(coefficient_array(self.K, self._coefficients()))
        self.reset()

    def _setup(self) -> None:
        """The model's constants (delay coefficients, kernels) and result arrays."""

    def _coefficients(self) -> dict[int, Any]:
        """The model's coefficients for :func:`coefficient_array` (set once, in ``coef``)."""
        p = self.params
        return {self.K.CLIP: p.clip, self.K.DC: p.dc}

    def reset(self) -> None:
        self.st.fill(0.0)
        self.c = 0  # index of the current ON/OFF buffers

    def load(self, grey: np.ndarray, first: bool) -> float:
        """Photoreceptors and this frame's ON/OFF channels (into :meth:`_channel_buffers`); returns ``sum |P|``."""
        scale = 1.0 if grey.dtype == np.uint8 else 255.0
        out = self._load_out
        out.fill(0.0)
        self.K.load_frame(grey, self.st, *self._channel_buffers(), scale, int(first), self.coef, self.blocks, out)
        return float(out[0])

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> float:
        """Take an event bin (H, W each, contrast in [0, 1]): the ON channel driven by ``P_on = 255 p_on``,
        the OFF channel by ``P_off = 255 p_off`` grey levels (:func:`event_bin`, one upload); ``P = P_on - P_off``.

        Returns ``sum (P_on + P_off)``, what the PM/FFI pathway takes (a frame's ``sum |P|``).
        """
        return self.load(event_bin(p_on, p_off), first)

    def _channel_buffers(self) -> tuple[int, int, int, int]:
        """``(ON(t-1), OFF(t-1), ON, OFF)`` buffers of :meth:`load`: the new channels go into the next
        ping-pong buffers, made current by :meth:`_next_buffers` when the layers run (an FFI-held frame
        keeps the old ones)."""
        c, n = self.c, 1 - self.c
        return self.on[c], self.off[c], self.on[n], self.off[n]

    def _next_buffers(self) -> tuple[int, int]:
        """Make the other ON/OFF buffers current: ``(current, previous)`` indices."""
        c, q = 1 - self.c, self.c  # new current, previous
        self.c = c
        return c, q

    def fields(self) -> dict[str, np.ndarray]:
        st = self.st.to_numpy()
        c = self.c
        out = {"P": st[self.K.P_], "ON": st[self.on[c]], "OFF": st[self.off[c]]}
        for k in self.LAYERS:
            out[k] = st[self.layout.index[k]]
        return out


def _lgmd2_coefficients(K: Any, p: Any, dt: int) -> dict[int, Any]:
    """LGMD2's coefficients (:func:`coefficient_array`)."""
    return {K.KN: p.k_on, K.AN: [lowpass_coefficient(dt, t) for t in p.tau_on],
            K.KF: p.k_off, K.AF: [lowpass_coefficient(dt, t) for t in p.tau_off],
            K.E_WEIGHTS: (p.w_on_exc, p.w_off_exc, p.w_onoff),
            K.DELTA_C: p.delta_c, K.C_W: p.c_w, K.C_DE: p.c_de, K.T_DE: p.t_de}


def _lgmd1_coefficients(K: Any, p: Any, dt: int) -> dict[int, Any]:
    """LGMD1's coefficients (:func:`coefficient_array`)."""
    return {K.K1: p.k_lateral, K.A1: [lowpass_coefficient(dt, t) for t in p.tau_lateral],
            K.W_I_ON: p.w_i_on, K.W_I_OFF: p.w_i_off,
            K.E_WEIGHTS: (p.w_on_exc, p.w_off_exc, p.w_onoff), K.T_S: p.t_s}


def _flgmd_coefficients(K: Any, p: Any, dt: int) -> dict[int, Any]:
    """F-LGMD's coefficients of both paths (:func:`coefficient_array`)."""
    a = [lowpass_coefficient(dt, t) for t in p.tau_lateral]
    w_on, w_off = p.feedback_stencils(dt)
    start_on, start_off = p.local_start_gains(dt)
    # edge and diagonal weights of Q = w_i sum K (1 - a) X(t-1), per channel (the lane load's)
    q_weights = [w * k * (1.0 - x) for w in (p.w_i_on, p.w_i_off) for k, x in zip(p.k_lateral, a)]
    return {K.K1: p.k_lateral, K.A1: a, K.W_I_ON: p.w_i_on, K.W_I_OFF: p.w_i_off, K.T_S: p.t_s,
            K.WN: w_on, K.WF: w_off, K.BETA_ON: p.beta_on, K.BETA_OFF: p.beta_off, K.QN1: q_weights,
            K.START_WN: (*start_on, *start_off), K.TOL: np.float32(p.tol), K.GROW: RESTART_GROWTH}


class TaichiLGMD2Backend(TaichiLGMDBackend):
    """LGMD2 layers in Taichi (see :class:`LGMD2`)."""

    MODEL = "lgmd2"
    LAYERS = ("I_on", "I_off", "S", "Ce", "G")

    def _setup(self) -> None:
        self._layers_out = np.zeros(2)  # lgmd2_layers' sum G, max |Ce|

    def _coefficients(self) -> dict[int, Any]:
        return {**super()._coefficients(), **_lgmd2_coefficients(self.K, self.params, self.dt)}

    def layers(self, w_on: float, w_off: float) -> tuple[float, float]:
        """Delayed inhibition, S, grouping (ON/OFF from :meth:`load`); returns ``(sum G, max |Ce|)``."""
        c, q = self._next_buffers()
        out = self._layers_out
        out.fill(0.0)
        self.K.lgmd2_layers(self.st, self.on[c], self.on[q], w_on, w_off, self.coef, self.blocks, out)
        return float(out[0]), float(out[1])


class LGMDLanes(LaneState):
    """The lane state of an LGMD-family model for one frame size (:class:`LaneTaichiLGMDBackend`).

    ``state``: one lane array (a vector ndarray, ``LANES`` float32 per element,
    shape (layers, H, NB); :func:`~cdnf_ti.kernels.common.lane_array`) in the lane
    layout of :mod:`cdnf_ti.kernels.common`, holding the model's layers and its channels'
    :attr:`CHANNEL_BUFFERS` buffers each (:class:`StateLayout`). Each backend has its own (each
    model its own subclass); the scratch is the process's (:class:`~cdnf_ti.backends.workspace.Scratch`).
    """

    MODEL: ClassVar[str]
    CHANNEL_BUFFERS: ClassVar[int] = 2

    def __init__(self, shape: tuple[int, int]):
        super().__init__(shape)
        C = kernels("common")
        H, W = shape
        _, nb = C.lane_layout(W)
        self.layout = StateLayout(kernels("lgmd").STATE_LAYERS[self.MODEL], self.CHANNEL_BUFFERS)
        self.state = C.lane_array(self.layout.size, H=H, NB=nb)
        # F-LGMD's constant inhibitions Q of ON and OFF: an array of their own (the lane kernels leave the
        # state's q_on/q_off planes unused): with Q a plane of the state, taichi 1.7.4's float reassociation
        # ordered the sums of feedback_local differently. The other models pass the state (not read).
        self.q = C.lane_array(2, H=H, NB=nb) if self.MODEL == "flgmd_onn" else self.state


class LaneTaichiLGMDBackend:
    """The fast CPU backend of an LGMD-family model: its layers in lane arrays, kernels compiled with
    explicit vector types (:func:`~cdnf_ti.taichi_runtime.vector_kernel`).

    Same interface, equations and results as the model's ndarray backend
    (:class:`TaichiLGMDBackend`); the kernels are the ``lanes_*`` ones of
    :mod:`cdnf_ti.kernels.lgmd`. Each backend owns its state (:attr:`workspace_type`) and
    its coefficient array ``coef`` (set once).

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
        self._load_bufs = np.zeros(4, np.int32)  # lgmd_lanes_load's channel buffers
        self._setup()
        ti = dsl()
        self.coef = ti.ndarray(ti.f32, self.K.N_COEFS)
        self.coef.from_numpy(coefficient_array(self.K, self._coefficients()))
        with self.lock:
            self.reset()

    def _setup(self) -> None:
        """The model's constants."""

    def _coefficients(self) -> dict[int, Any]:
        """The model's coefficients for :func:`coefficient_array` (set once, in ``coef``)."""
        p = self.params
        return {self.K.CLIP: p.clip, self.K.DC: p.dc}

    def _acquire(self) -> LGMDLanes:
        """This backend's arrays."""
        return self.ws

    def _on(self, b: int) -> int:
        """Buffer ``b`` of the ON channel (its index in the state)."""
        return self.ws.layout.on[b]

    def _off(self, b: int) -> int:
        """Buffer ``b`` of the OFF channel (its index in the state)."""
        return self.ws.layout.off[b]

    # -- backend interface ---------------------------------------------------
    def reset(self) -> None:
        self._acquire().state.fill(0.0)
        self._reset_buffers()

    def load_on_off(self, p_on: np.ndarray, p_off: np.ndarray, first: bool) -> float:
        """Take an event bin (H, W each, contrast in [0, 1]): the ON channel driven by ``P_on = 255 p_on``,
        the OFF channel by ``P_off = 255 p_off`` grey levels (:func:`event_bin`, one upload); ``P = P_on - P_off``.

        Returns ``sum (P_on + P_off)``, what the PM/FFI pathway takes (a frame's ``sum |P|``).
        """
        return self.load(event_bin(p_on, p_off), first)

    def _reset_buffers(self) -> None:
        """Back to the first buffers of the channels."""

    def _load(self, grey: np.ndarray, first: bool, c_on: int, s_on: int, c_off: int, s_off: int,
              feedback: bool = False) -> float:
        """:func:`cdnf_ti.kernels.lgmd.lgmd_lanes_load`: channels ``s`` from ``c``; returns ``sum |P|``.

        ``feedback``: F-LGMD's drives, constant inhibition and iterate's start too.
        """
        ws = self._acquire()
        scale = 1.0 if grey.dtype == np.uint8 else 255.0
        out = self._load_out
        out.fill(0.0)
        bufs = self._load_bufs
        bufs[:] = self._on(c_on), self._on(s_on), self._off(c_off), self._off(s_off)  # kernels.lgmd.L_C_ON, ...
        self.K.lgmd_lanes_load(grey, ws.state, ws.q, bufs, scale, int(first), self.coef, self.W, feedback, out)
        return float(out[0])

    def _channel_buffers(self) -> tuple[int, int]:
        """Buffers of the ON and OFF channels that :meth:`fields` shows."""
        raise NotImplementedError

    def fields(self) -> dict[str, np.ndarray]:
        ws = self._acquire()
        st = ws.state.to_numpy()
        b_on, b_off = self._channel_buffers()
        out = {"P": ws.frame(st[self.K.P_]), "ON": ws.frame(st[self._on(b_on)]),
               "OFF": ws.frame(st[self._off(b_off)])}
        for name in self.FIELD_LAYERS:
            out[name] = ws.frame(st[ws.layout.index[name]])
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
    MODEL = "lgmd2"


class LaneTaichiLGMD2Backend(PingPongLaneLGMDBackend):
    """LGMD2 layers on lane fields (see :class:`LGMD2`): a frame's layers in one launch."""

    workspace_type = _LGMD2Lanes
    FIELD_LAYERS = ("I_on", "I_off", "S", "Ce", "G")

    def _setup(self) -> None:
        self._layers_out = np.zeros(2)  # lgmd2_lanes_layers' sum G, max |Ce|

    def _coefficients(self) -> dict[int, Any]:
        return {**super()._coefficients(), **_lgmd2_coefficients(self.K, self.params, self.dt)}

    def layers(self, w_on: float, w_off: float) -> tuple[float, float]:
        """Delayed inhibition, S, grouping (ON/OFF from :meth:`load`); returns ``(sum G, max |Ce|)``."""
        ws = self._acquire()
        c, q = self._next_buffers()
        out = self._layers_out
        out.fill(0.0)
        self.K.lgmd2_lanes_layers(ws.state, self._on(c), self._on(q), w_on, w_off, self.coef, self.nw, self.W, out)
        return float(out[0]), float(out[1])


class TaichiLGMD1Backend(TaichiLGMDBackend):
    """LGMD1 layers in Taichi (see :class:`LGMD1`)."""

    MODEL = "lgmd1"
    LAYERS = ("I_on", "E_off", "S", "G")

    def _setup(self) -> None:
        self._layers_out = np.zeros(1)  # lgmd1_layers' sum G

    def _coefficients(self) -> dict[int, Any]:
        return {**super()._coefficients(), **_lgmd1_coefficients(self.K, self.params, self.dt)}

    def layers(self) -> float:
        """Delayed spreads, S (thresholded), G (ON/OFF from :meth:`load`); returns ``sum G``."""
        c, q = self._next_buffers()
        out = self._layers_out
        out.fill(0.0)
        self.K.lgmd1_layers(self.st, self.on[c], self.on[q], self.coef, self.blocks, out)
        return float(out[0])


class _LGMD1Lanes(LGMDLanes):
    MODEL = "lgmd1"


class LaneTaichiLGMD1Backend(PingPongLaneLGMDBackend):
    """LGMD1 layers on lane fields (see :class:`LGMD1`): a frame's layers in one launch."""

    workspace_type = _LGMD1Lanes
    FIELD_LAYERS = ("I_on", "E_off", "S", "G")

    def _setup(self) -> None:
        self._layers_out = np.zeros(1)  # lgmd1_lanes_layers' sum G

    def _coefficients(self) -> dict[int, Any]:
        return {**super()._coefficients(), **_lgmd1_coefficients(self.K, self.params, self.dt)}

    def layers(self) -> float:
        """Delayed spreads, S (thresholded), G (ON/OFF from :meth:`load`); returns ``sum G``."""
        ws = self._acquire()
        c, q = self._next_buffers()
        out = self._layers_out
        out.fill(0.0)
        self.K.lgmd1_lanes_layers(ws.state, self._on(c), self._on(q), self.coef, self.nw, self.W, out)
        return float(out[0])


class TaichiFLGMDBackend(TaichiLGMDBackend):
    """F-LGMD layers in Taichi (see :class:`FLGMDONn`): feedback iteration on the ON/OFF channels.

    Per frame: :meth:`load` writes the drives ``ON0``/``OFF0``; :meth:`prepare` the
    constant inhibition ``Q`` of both channels and the iterate's start;
    :meth:`feedback_iterate` one relaxed update; :meth:`finish` the layers at the
    fixed point.
    """

    MODEL = "flgmd_onn"
    LAYERS = ("S_on", "S_off", "S", "G")
    #: Current, previous (settled) and scratch buffers per channel.
    CHANNEL_BUFFERS = 3

    def _setup(self) -> None:
        self._iterate_out = np.zeros(2)  # flgmd_iterate's residuals of ON, OFF
        self._finish_out = np.zeros(1)  # flgmd_finish's sum G

    def _coefficients(self) -> dict[int, Any]:
        return {**super()._coefficients(), **_flgmd_coefficients(self.K, self.params, self.dt)}

    def reset(self) -> None:
        super().reset()
        self.pi = 1  # index of the previous (settled) buffers
        self.ni = 2  # scratch buffers

    def _channel_buffers(self) -> tuple[int, int, int, int]:
        """The drives ``ON0``/``OFF0`` from the settled channels ``on[c]``/``off[c]``."""
        index = self.layout.index
        return self.on[self.c], self.off[self.c], index["on0"], index["off0"]

    def prepare(self) -> None:
        # the settled current buffers become the previous ones
        self.pi, self.c = self.c, self.pi
        self.K.flgmd_prepare(self.st, self.on[self.c], self.off[self.c], self.on[self.pi], self.off[self.pi],
                             self.coef, self.blocks)

    def feedback_iterate(self, lam: float, mom: float = 0.0) -> tuple[float, float]:
        """One update ``X <- X + mom (X - X_prev) + lam (T(X) - X)``; returns the residuals before it."""
        p = self.params
        c, n = self.c, self.ni
        with_off = p.beta_off != 0.0
        out = self._iterate_out
        out.fill(0.0)
        self.K.flgmd_iterate(self.st, self.on[c], self.off[c], self.on[n], self.off[n], lam, mom, self.coef,
                             self.blocks, with_off, out)
        if with_off:
            self.c, self.ni = n, c
        else:
            # only ON was iterated: swap the ON buffers, keep OFF in place
            self.on[c], self.on[n] = self.on[n], self.on[c]
        return float(out[0]), float(out[1])

    def finish(self) -> float:
        c = self.c
        out = self._finish_out
        out.fill(0.0)
        self.K.flgmd_finish(self.st, self.on[c], self.off[c], self.coef, self.blocks, out)
        return float(out[0])

    def hold(self) -> None:
        """FFI-held frame: the channels keep their previous values (nothing to do)."""


class _FLGMDLanes(LGMDLanes):
    MODEL = "flgmd_onn"
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
        self.steps = MAX_STEPS  # updates per solve launch (feedback_iterate_many)
        self._sum_g: float | None = None  # sum G computed by a converged solve launch
        self._record = LaunchRecord(2)  # flgmd_lanes_solve's coefficients in, residuals out
        self._solve_out = np.zeros(1)  # flgmd_lanes_solve's sum G (-1: not converged)
        self._finish_out = np.zeros(1)  # flgmd_lanes_finish's sum G
        self._bufs = np.zeros(7, np.int32)  # flgmd_lanes_solve's buffers (kernels.lgmd.B_ON...), updates, workers, OFF

    def _coefficients(self) -> dict[int, Any]:
        return {**super()._coefficients(), **_flgmd_coefficients(self.K, self.params, self.dt)}

    def _reset_buffers(self) -> None:
        self.settled = [0, 0]  # buffer of the settled ON, OFF channel
        self.iterate = [1, 1]  # buffer of the current iterate of ON, OFF

    def load(self, grey: np.ndarray, first: bool) -> float:
        """Photoreceptors, drives, constant inhibition and the iterate's start; returns ``sum |P|``."""
        self.iterate = [(c + 1) % 3 for c in self.settled]
        self._sum_g = None
        return self._load(grey, first, self.settled[0], self.iterate[0], self.settled[1], self.iterate[1], True)

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
        rec, out, bufs = self._record, self._solve_out, self._bufs
        bufs[:] = (self._on(cur[0]), self._on(other[0]), self._off(cur[1]), self._off(other[1]),  # B_ON, ...
                   len(coefs), self.nw, int(with_off))  # B_N, B_NW, B_WITH_OFF
        self.K.flgmd_lanes_solve(ws.state, ws.q, bufs, rec.start(coefs), self.coef, self.W, out)
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
        out = self._finish_out
        out.fill(0.0)
        ws = self._acquire()
        self.K.flgmd_lanes_finish(ws.state, ws.q, self._on(self.settled[0]), self._off(self.settled[1]),
                                  self.coef, self.W, out)
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
