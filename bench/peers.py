"""Peer implementations of the C-DNF equations, for throughput comparisons.

Each peer is a backend with the same interface as
:class:`cdnf_ti.reference.NumpyCDNFBackend` (``load``, ``contrast_iterate``,
``summation_input``, ``summation_iterate``, ``mean_activation``, ...), so
:class:`PeerCDNF` drives it with exactly the model logic and fixed-point
schedule of :class:`cdnf_ti.CDNF` (same tolerance and damping controller), the
paper's way: plain iteration, each frame starting from the previous frame's solution
(``scheme="plain"``, ``start="previous"``). Fields are float32, like the Taichi backend.

* ``scipy``: :func:`scipy.ndimage.correlate` (the 3x3 ``W_c`` and the 7x7 ``W_s``
  as dense 2-D correlations), NumPy ufuncs.
* ``opencv``: dense OpenCV + NumPy done well: preallocated float32 buffers,
  in-place ufuncs, ``cv2.filter2D`` for ``W_c`` and ``cv2.sepFilter2D`` for the
  two separable Gaussians of ``W_s``.
* ``torch``: PyTorch CPU ``conv2d`` (only when ``torch`` is installed).
"""
from __future__ import annotations

import importlib.util
from typing import Callable

import cv2
import numpy as np

from ..models.cdnf import CDNF
from ..params import THETA_SCALE, CDNFParams, contrast_kernel, dog_kernel, dog_profiles, resting_levels
from ..reference import RestingFields

_SCIPY_MODE = {"replicate": "nearest", "reflect": "mirror", "zero": "constant"}
_CV_BORDER = {"replicate": cv2.BORDER_REPLICATE, "reflect": cv2.BORDER_REFLECT_101,
              "zero": cv2.BORDER_CONSTANT}


class _PeerBase(RestingFields):
    """State and the parts every peer shares (float32 fields, NumPy ufuncs)."""

    name = "peer"

    def __init__(self, params: CDNFParams, shape: tuple[int, int]):
        self.params = params
        self.shape = tuple(shape)
        f = np.float32
        self.L = np.zeros(self.shape, f)
        self.P = np.zeros(self.shape, f)
        self.P_on = np.zeros(self.shape, f)
        self.P_off = np.zeros(self.shape, f)
        self.S = np.zeros(self.shape, f)
        self.u0, self.v0 = resting_levels(params)
        self.u_on = np.full(self.shape, self.u0, f)
        self.u_off = np.full(self.shape, self.u0, f)
        self.v = np.full(self.shape, self.v0, f)
        self.tmp = np.zeros(self.shape, f)
        self.d = np.zeros(self.shape, f)

    def load(self, grey: np.ndarray, first: bool) -> None:
        g = grey.astype(np.float32)
        if grey.dtype == np.uint8:
            g *= np.float32(1.0 / 255.0)
        if first:
            self.P.fill(0.0)
        else:
            np.subtract(g, self.L, out=self.P)
        self.L[...] = g
        np.maximum(self.P, 0.0, out=self.P_on)
        np.negative(self.P, out=self.P_off)
        np.maximum(self.P_off, 0.0, out=self.P_off)

    def clear_input(self) -> None:
        self.P.fill(0.0)
        self.P_on.fill(0.0)
        self.P_off.fill(0.0)

    # the lateral correlations: implemented by each peer
    def corr_c(self, u: np.ndarray, out: np.ndarray) -> None:
        raise NotImplementedError

    def corr_s(self, v: np.ndarray, out: np.ndarray) -> None:
        raise NotImplementedError

    def _relax(self, u: np.ndarray, inp: np.ndarray, lam: float, corr: Callable) -> float:
        """``d = inp - h + tanh(corr(u) / 2) - u``; ``u += lam d``; returns max |d|."""
        t, d = self.tmp, self.d
        corr(u, t)
        t *= np.float32(0.5)
        np.tanh(t, out=t)
        np.subtract(inp, u, out=d)
        d += t
        d -= np.float32(self.params.h)
        r = float(np.abs(d).max())
        if lam != 1.0:
            d *= np.float32(lam)
        u += d
        return r

    def contrast_iterate(self, lam: float) -> tuple[float, float]:
        # Jacobi: both fields use their previous iterate (as the reference does).
        return (self._relax(self.u_on, self.P_on, lam, self.corr_c),
                self._relax(self.u_off, self.P_off, lam, self.corr_c))

    def summation_input(self) -> None:
        p = self.params
        a, b = self.tmp, self.S
        np.maximum(self.u_on, 0.0, out=a)
        np.tanh(a, out=a)
        a *= np.float32(p.alpha_on * THETA_SCALE)
        np.maximum(self.u_off, 0.0, out=b)
        np.tanh(b, out=b)
        b *= np.float32(p.alpha_off * THETA_SCALE)
        b += a

    def summation_iterate(self, lam: float) -> tuple[float]:
        return (self._relax(self.v, self.S, lam, self.corr_s),)

    def mean_activation(self) -> float:
        a = np.maximum(self.v, 0.0, out=self.tmp)
        np.tanh(a, out=a)
        return float(a.sum(dtype=np.float64) * THETA_SCALE / a.size)

    def fields(self) -> dict[str, np.ndarray]:
        return {"u_on": self.u_on.copy(), "u_off": self.u_off.copy(), "v": self.v.copy(), "P": self.P.copy()}


class ScipyBackend(_PeerBase):
    """C-DNF with :func:`scipy.ndimage.correlate` (dense 2-D kernels), float32."""

    name = "scipy"

    def __init__(self, params: CDNFParams, shape: tuple[int, int]):
        super().__init__(params, shape)
        from scipy import ndimage

        self._nd = ndimage
        self.w_c = contrast_kernel(params.sigma_c).astype(np.float32)
        self.w_s = dog_kernel(params).astype(np.float32)
        self.mode = _SCIPY_MODE[params.border]

    def corr_c(self, u: np.ndarray, out: np.ndarray) -> None:
        self._nd.correlate(u, self.w_c, output=out, mode=self.mode, cval=0.0)

    def corr_s(self, v: np.ndarray, out: np.ndarray) -> None:
        self._nd.correlate(v, self.w_s, output=out, mode=self.mode, cval=0.0)


class OpenCVBackend(_PeerBase):
    """C-DNF with OpenCV filters and in-place NumPy ufuncs on preallocated float32 buffers.

    ``W_c`` is ``cv2.filter2D`` (3x3); ``W_s = A g1 g1^T - B g2 g2^T`` is two
    ``cv2.sepFilter2D`` passes combined in place.
    """

    name = "opencv"

    def __init__(self, params: CDNFParams, shape: tuple[int, int]):
        super().__init__(params, shape)
        self.w_c = contrast_kernel(params.sigma_c).astype(np.float32)
        g1, g2 = dog_profiles(params)
        self.k1 = (g1 * np.sqrt(params.A)).astype(np.float32)
        self.k2 = (g2 * np.sqrt(params.B)).astype(np.float32)
        self.border = _CV_BORDER[params.border]
        self.t2 = np.zeros(self.shape, np.float32)

    def corr_c(self, u: np.ndarray, out: np.ndarray) -> None:
        cv2.filter2D(u, cv2.CV_32F, self.w_c, dst=out, borderType=self.border)

    def corr_s(self, v: np.ndarray, out: np.ndarray) -> None:
        cv2.sepFilter2D(v, cv2.CV_32F, self.k1, self.k1, dst=out, borderType=self.border)
        cv2.sepFilter2D(v, cv2.CV_32F, self.k2, self.k2, dst=self.t2, borderType=self.border)
        out -= self.t2


class TorchBackend(_PeerBase):
    """C-DNF with PyTorch CPU ``conv2d`` (float32); needs ``torch``."""

    name = "torch"

    def __init__(self, params: CDNFParams, shape: tuple[int, int]):
        super().__init__(params, shape)
        import torch
        import torch.nn.functional as F

        self._torch, self._F = torch, F
        self.w_c = torch.from_numpy(contrast_kernel(params.sigma_c).astype(np.float32))[None, None]
        self.w_s = torch.from_numpy(dog_kernel(params).astype(np.float32))[None, None]
        self.pad = {"replicate": "replicate", "reflect": "reflect", "zero": "constant"}[params.border]

    def _corr(self, x: np.ndarray, w, out: np.ndarray) -> None:
        r = w.shape[-1] // 2
        t = self._torch.from_numpy(x)[None, None]
        t = self._F.pad(t, (r, r, r, r), mode=self.pad)
        out[...] = self._F.conv2d(t, w)[0, 0].numpy()

    def corr_c(self, u: np.ndarray, out: np.ndarray) -> None:
        self._corr(u, self.w_c, out)

    def corr_s(self, v: np.ndarray, out: np.ndarray) -> None:
        self._corr(v, self.w_s, out)


def available_peers() -> dict[str, type[_PeerBase]]:
    """Peer backends whose libraries are installed, by name."""
    peers: dict[str, type[_PeerBase]] = {}
    if importlib.util.find_spec("scipy") is not None:
        peers["scipy"] = ScipyBackend
    peers["opencv"] = OpenCVBackend
    if importlib.util.find_spec("torch") is not None:
        peers["torch"] = TorchBackend
    return peers


class PeerCDNF(CDNF):
    """:class:`cdnf_ti.CDNF` driven by a peer backend (same model logic and schedule).

    Parameters
    ----------
    peer : str
        ``"scipy"``, ``"opencv"`` or ``"torch"``.
    params : CDNFParams, optional
    """

    def __init__(self, peer: str, params: CDNFParams | None = None, fps: float = 30.0):
        peers = available_peers()
        if peer not in peers:
            raise ValueError(f"peer {peer!r} is not available here; available: {', '.join(peers)}")
        # the paper's plain scheme from the previous solution: the peers implement the relaxed update only
        params = (params or CDNFParams()).replace(scheme="plain", start="previous")
        super().__init__(params, backend="numpy", fps=fps)
        self.peer = peer
        self._peer_cls = peers[peer]

    def _numpy_backend(self, shape: tuple[int, int]) -> "_PeerBase":
        return self._peer_cls(self.params, shape)
