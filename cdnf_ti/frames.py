"""Frame conversion and frame sources: video files, image folders, .npy arrays.

Every problem with an input becomes an :class:`~cdnf_ti.errors.InputError`
whose one-line message names the file.
"""
from __future__ import annotations

import os
import queue
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator, TypeVar

import cv2
import numpy as np

from .errors import InputError
from .events.readers import is_event_file

T = TypeVar("T")

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")


def to_grey(frame: np.ndarray) -> np.ndarray:
    """Convert a frame to the grey form the models take.

    Parameters
    ----------
    frame : ndarray
        (H, W) uint8 (0..255) or float in [0, 1]; (H, W, 3) BGR uint8 (or float
        in [0, 1]); (H, W, 1).

    Returns
    -------
    ndarray, shape (H, W)
        uint8 grey, or float32 grey in [0, 1]. BGR is converted with the
        ITU-R BT.601 luma weights (``cv2.COLOR_BGR2GRAY``).

    Raises
    ------
    ValueError
        Unsupported shape or dtype, or float values outside [0, 1].
    """
    a = np.asarray(frame)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim == 3 and a.shape[2] in (3, 4):
        if a.dtype == np.uint8:
            code = cv2.COLOR_BGR2GRAY if a.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
            a = cv2.cvtColor(np.ascontiguousarray(a), code)
        elif np.issubdtype(a.dtype, np.floating):
            code = cv2.COLOR_BGR2GRAY if a.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
            a = cv2.cvtColor(np.ascontiguousarray(a, dtype=np.float32), code)
        else:
            raise ValueError(f"colour frames must be uint8 or float, got {a.dtype}")
    if a.ndim != 2:
        raise ValueError(f"a frame must be (H, W), (H, W, 1) or (H, W, 3) BGR; got shape {a.shape}")
    if a.shape[0] < 2 or a.shape[1] < 2:
        raise ValueError(f"a frame must be at least 2x2 pixels; got {a.shape}")
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    if np.issubdtype(a.dtype, np.floating) or a.dtype == np.bool_:
        a = np.ascontiguousarray(a, dtype=np.float32)
        lo, hi = float(a.min()), float(a.max())
        if not (np.isfinite(lo) and np.isfinite(hi)) or lo < -1e-6 or hi > 1 + 1e-6:
            raise ValueError(f"float frames must lie in [0, 1]; got values in [{lo:g}, {hi:g}]")
        return a
    if np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"integer frames must be uint8 (0..255); got {a.dtype}")
    raise ValueError(f"unsupported frame dtype {a.dtype}")


@dataclass(frozen=True)
class ColourFrame:
    """One decoded frame in the two forms the models take (:meth:`~cdnf_ti.models.base.Model.frame_colour`).

    Attributes
    ----------
    grey : ndarray, shape (H, W)
        The frame made grey once, by :func:`to_grey` (uint8, or float32 in [0, 1]).
    bgr : ndarray, shape (H, W, 3) or (H, W)
        The frame as decoded: BGR uint8 (or float) where the input has colour, else the grey frame.
    """

    grey: np.ndarray
    bgr: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """The frame size (H, W) in pixels."""
        return self.grey.shape

    @classmethod
    def of(cls, frame: np.ndarray) -> "ColourFrame":
        """Both forms of a decoded ``frame``: its grey by :func:`to_grey`, its colour as it is (BGRA: without the
        alpha channel; (H, W) or (H, W, 1): the grey frame)."""
        grey = to_grey(frame)
        bgr = np.asarray(frame)
        return cls(grey, bgr[:, :, :3] if bgr.ndim == 3 and bgr.shape[2] in (3, 4) else grey)


@dataclass
class FrameSource:
    """A re-iterable stream of frames from one input.

    Attributes
    ----------
    path : str
        The input's path (or a stimulus name).
    fps : float
        Frame rate (30 when the input does not say).
    n_frames : int or None
        Frame count when known in advance.
    shape : (H, W)
        Frame size in pixels.
    """

    path: str
    fps: float
    n_frames: int | None
    shape: tuple[int, int]
    _iter_factory: object = None
    #: Frames may be decoded on a background thread (file decoding only; generated
    #: sources that launch Taichi kernels must stay on the caller's thread).
    background_decode: bool = False

    def __iter__(self) -> Iterator[np.ndarray]:
        return self._iter_factory()  # type: ignore[operator]

    @property
    def name(self) -> str:
        """Clip name: the file name without extension."""
        return Path(self.path).stem if os.path.sep in self.path or "." in self.path else self.path


def _checked(path: str, frames: Iterator[np.ndarray], shape: tuple[int, int]) -> Iterator[np.ndarray]:
    """Yield frames, raising InputError on a size change."""
    for t, f in enumerate(frames):
        if f.shape[:2] != shape:
            raise InputError(path, f"frame {t} is {f.shape[1]}x{f.shape[0]} but frame 0 is "
                                   f"{shape[1]}x{shape[0]} (frame size changed mid-video)")
        yield f


#: Frame rate assumed for inputs that carry none (image folders, .npy arrays), frames/s.
DEFAULT_FPS = 30.0
COLOR_ORDERS = ("bgr", "rgb")


def _fps_arg(path: str, fps: float | None) -> float | None:
    if fps is None:
        return None
    fps = float(fps)
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(path, f"frame rate must be a finite number > 0, got {fps:g}")
    return fps


#: FOURCCs of motion-JPEG streams, whose every frame states its own size (:func:`_packet_sizes`).
MJPEG_FOURCCS = ("MJPG", "JPEG", "MJPA", "MJPB", "AVRN", "DMB1")
#: JPEG start-of-frame markers (they hold the frame height and width).
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def jpeg_size(data: bytes) -> tuple[int, int] | None:
    """The (width, height) in pixels that a JPEG image states in its start-of-frame marker.

    Parameters
    ----------
    data : bytes
        One JPEG image (a motion-JPEG frame).

    Returns
    -------
    (int, int) or None
        ``None`` when ``data`` is not a JPEG or its header is cut short before the size.
    """
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # a fill byte
            i += 1
        elif marker in _JPEG_SOF:
            if i + 9 > len(data):
                return None
            return int.from_bytes(data[i + 7:i + 9], "big"), int.from_bytes(data[i + 5:i + 7], "big")
        elif marker == 0x01 or 0xD0 <= marker <= 0xD8:  # markers without a length
            i += 2
        else:
            i += 2 + int.from_bytes(data[i + 2:i + 4], "big")
    return None


def _packet_sizes(path: str) -> Iterator[tuple[int, int] | None]:
    """The frame sizes a motion-JPEG video's packets state, in order (``None`` for one that states none).

    OpenCV rescales every decoded frame to the first frame's size, so a size change
    cannot be seen in the decoded frames; the packets, read undecoded (OpenCV's raw
    mode, ``CAP_PROP_FORMAT = -1``), still state it.
    """
    c = cv2.VideoCapture(path)
    try:
        if not c.isOpened() or not c.set(cv2.CAP_PROP_FORMAT, -1):
            return
        while True:
            level = cv2.utils.logging.getLogLevel()
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)  # raw mode warns on every packet
            try:
                ok, packet = c.read()
            finally:
                cv2.utils.logging.setLogLevel(level)
            if not ok or packet is None:
                return
            yield jpeg_size(packet.tobytes())
    finally:
        c.release()


def _fourcc(cap: "cv2.VideoCapture") -> str:
    code = int(cap.get(cv2.CAP_PROP_FOURCC) or 0)
    return code.to_bytes(4, "little").decode("latin-1").upper()


def open_video(path: str | os.PathLike, fps: float | None = None) -> FrameSource:
    """Open an OpenCV-readable video file (BGR uint8 frames).

    ``fps`` overrides the frame rate the container states (used when it is 0,
    absurd or missing: 30). A motion-JPEG frame whose size differs from the size the
    video states (OpenCV would rescale it silently) is an :class:`InputError`:
    ``frame N is WxH, the video states W0xH0``.
    """
    path = str(path)
    override = _fps_arg(path, fps)
    cap = cv2.VideoCapture(path)
    if not cap.isOpened():
        cap.release()
        raise InputError(path, "cannot open as a video (unsupported format or corrupt file)")
    ok, first = cap.read()
    fps = cap.get(cv2.CAP_PROP_FPS) or 30.0
    count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
    stated = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH) or 0), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT) or 0))
    mjpeg = _fourcc(cap) in MJPEG_FOURCCS
    cap.release()
    if not ok or first is None:
        raise InputError(path, "contains no decodable frames (empty or corrupt video)")
    if not (0 < fps < 1000):
        fps = DEFAULT_FPS
    if override is not None:
        fps = override
    shape = first.shape[:2]
    if min(stated) <= 0:  # the container states no size: the first frame's
        stated = (shape[1], shape[0])

    def gen() -> Iterator[np.ndarray]:
        c = cv2.VideoCapture(path)
        if not c.isOpened():
            raise InputError(path, "cannot open as a video (unsupported format or corrupt file)")
        sizes = _packet_sizes(path) if mjpeg else None
        try:
            t = 0
            while True:
                ok, f = c.read()
                if not ok or f is None:
                    break
                size = None if sizes is None else next(sizes, None)
                if size is not None and size != stated:
                    raise InputError(path, f"frame {t} is {size[0]}x{size[1]}, the video states "
                                           f"{stated[0]}x{stated[1]} (frame size changed mid-video)")
                t += 1
                yield f
            if t == 0:
                raise InputError(path, "contains no decodable frames (empty or corrupt video)")
            if count > 0 and t < count - max(2, count // 50):
                raise InputError(path, f"decoding stopped at frame {t} of {count} "
                                       "(truncated or corrupt video)")
        finally:
            if sizes is not None:
                sizes.close()
            c.release()

    return FrameSource(path, float(fps), count if count > 0 else None, shape,
                       lambda: _checked(path, gen(), shape), background_decode=True)


def open_image_folder(path: str | os.PathLike, fps: float | None = None) -> FrameSource:
    """Open a folder of images as frames, in sorted file-name order.

    Images are decoded by OpenCV (colour comes out BGR, as :func:`to_grey` expects).
    A folder carries no frame rate: ``fps`` (default :data:`DEFAULT_FPS`).
    """
    path = str(path)
    fps = _fps_arg(path, fps) or DEFAULT_FPS
    files = sorted(p for p in Path(path).iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS)
    if not files:
        raise InputError(path, f"folder holds no image files ({', '.join(IMAGE_EXTENSIONS)})")
    first = cv2.imread(str(files[0]), cv2.IMREAD_UNCHANGED)
    if first is None:
        raise InputError(files[0], "cannot read image (unsupported or corrupt)")
    shape = first.shape[:2]

    def gen() -> Iterator[np.ndarray]:
        for fp in files:
            img = cv2.imread(str(fp), cv2.IMREAD_UNCHANGED)
            if img is None:
                raise InputError(fp, "cannot read image (unsupported or corrupt)")
            if img.dtype == np.uint16:
                img = (img / 257.0).round().astype(np.uint8)
            if img.shape[:2] != shape:
                raise InputError(fp, f"image is {img.shape[1]}x{img.shape[0]} but the first image is "
                                     f"{shape[1]}x{shape[0]} (frame size changed mid-sequence)")
            yield img

    return FrameSource(path, fps, len(files), shape, gen, background_decode=True)


def open_npy(path: str | os.PathLike, fps: float | None = None, color_order: str = "bgr") -> FrameSource:
    """Open a ``.npy`` array of frames: (T, H, W) or (T, H, W, 3), uint8 or float in [0, 1].

    Parameters
    ----------
    fps : float, optional
        Frame rate (an array carries none; default :data:`DEFAULT_FPS`).
    color_order : {"bgr", "rgb"}
        Channel order of (T, H, W, 3) arrays. ``bgr`` (default) is OpenCV's;
        arrays made with imageio, PIL or matplotlib are ``rgb``. Grey is
        computed with the BT.601 weights, so the order matters.
    """
    path = str(path)
    fps = _fps_arg(path, fps) or DEFAULT_FPS
    if color_order not in COLOR_ORDERS:
        raise InputError(path, f"unknown colour order {color_order!r}; choose bgr or rgb")
    try:
        arr = np.load(path, mmap_mode="r", allow_pickle=False)
    except Exception as e:  # noqa: BLE001 - any failure here is a bad file
        if "allow_pickle" in str(e):  # numpy's wording for any file that is not a plain .npy array
            raise InputError(path, "not a NumPy .npy array file (np.save of a (T, H, W) array)") from None
        raise InputError(path, f"cannot read as a NumPy array ({type(e).__name__}: {e})".splitlines()[0]) from None
    if arr.ndim not in (3, 4) or (arr.ndim == 4 and arr.shape[3] not in (1, 3)):
        raise InputError(path, f"array must be (T, H, W) or (T, H, W, 3); got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise InputError(path, "array holds no frames")
    shape = tuple(arr.shape[1:3])

    flip = color_order == "rgb" and arr.ndim == 4 and arr.shape[3] == 3

    def gen() -> Iterator[np.ndarray]:
        for t in range(arr.shape[0]):
            f = np.asarray(arr[t])
            yield np.ascontiguousarray(f[:, :, ::-1]) if flip else f

    return FrameSource(path, fps, int(arr.shape[0]), shape, gen, background_decode=True)


def open_source(path: str | os.PathLike, fps: float | None = None, color_order: str = "bgr") -> FrameSource:
    """Open any supported input: video file, image folder or ``.npy`` array.

    Parameters
    ----------
    fps : float, optional
        Frame rate in frames/s: overrides a video's own; image folders and
        ``.npy`` arrays carry none and default to :data:`DEFAULT_FPS` (30).
    color_order : {"bgr", "rgb"}
        Channel order of colour ``.npy`` arrays (see :func:`open_npy`); files
        decoded by OpenCV are always BGR.

    Raises
    ------
    InputError
        Missing, unreadable, empty or corrupt input (message names the file).
    """
    p = Path(path)
    if not p.exists():
        raise InputError(path, "no such file or folder")
    if p.is_dir():
        return open_image_folder(p, fps)
    if not os.access(p, os.R_OK):
        raise InputError(path, "permission denied")
    if p.stat().st_size == 0:
        raise InputError(path, "file is empty")
    if is_event_file(p):
        raise InputError(path, "is an event-camera recording, not frames: 'python -m cdnf_ti.run FILE' runs the "
                               "models on it (docs/EVENTS.md); 'python -m cdnf_ti.run events --info' "
                               "summarises it")
    if p.suffix.lower() == ".npy":
        return open_npy(p, fps, color_order)
    if p.suffix.lower() in IMAGE_EXTENSIONS:
        raise InputError(path, "is a single image; give a video, a folder of images or a .npy array")
    return open_video(p, fps)


def _converted_frames(source: FrameSource, convert) -> Iterator:
    for t, f in enumerate(source):
        try:
            yield convert(f)
        except ValueError as e:
            raise InputError(source.path, f"frame {t}: {e}") from None


def iter_grey(source: FrameSource, prefetch: int = 4) -> Iterator[np.ndarray]:
    """Frames of ``source`` converted by :func:`to_grey`, with errors naming the file.

    Parameters
    ----------
    source : FrameSource
    prefetch : int
        For file sources, decode and convert up to this many frames ahead on a
        background thread, off the model's critical path (0 = decode inline).
    """
    return iter_frames(source, colour=False, prefetch=prefetch)


def iter_frames(source: FrameSource, colour: bool, prefetch: int = 4) -> Iterator:
    """Frames of ``source`` for models: grey (:func:`iter_grey`), or with ``colour`` each frame in both forms.

    Parameters
    ----------
    source : FrameSource
    colour : bool
        False: grey (H, W) arrays. True: :class:`ColourFrame` items (decoded once, made grey once), for a
        pass in which some model takes colour frames (:func:`~cdnf_ti.models.base.takes_colour`).
    prefetch : int
        For file sources, decode and convert up to this many frames ahead on a
        background thread, off the model's critical path (0 = decode inline).
    """
    frames = _converted_frames(source, ColourFrame.of if colour else to_grey)
    if prefetch > 0 and source.background_decode:
        return prefetched(frames, prefetch)
    return frames


def prefetched(items: Iterable[T], depth: int = 4) -> Iterator[T]:
    """Iterate ``items`` on a background thread, up to ``depth`` items ahead.

    Items come out in order; an exception raised while producing an item is
    re-raised in the caller at that point; closing the returned generator early
    stops the thread. OpenCV decoding releases the GIL, so decode overlaps
    with the caller's work.
    """
    q: queue.Queue = queue.Queue(maxsize=max(1, depth))
    stop = threading.Event()

    def put(item: tuple) -> bool:
        while not stop.is_set():
            try:
                q.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        try:
            for x in items:
                if not put((_ITEM, x)):
                    return
            put((_END, None))
        except BaseException as e:  # noqa: BLE001 - handed to the consumer
            put((_ERROR, e))

    thread = threading.Thread(target=work, name="cdnf_ti-decode", daemon=True)

    def consume() -> Iterator[T]:
        thread.start()  # only once iteration begins, so an unused stream leaves no thread
        try:
            while True:
                kind, x = q.get()
                if kind is _ITEM:
                    yield x
                elif kind is _END:
                    return
                else:
                    raise x
        finally:
            stop.set()
            thread.join(timeout=5)

    return consume()


_ITEM, _END, _ERROR = object(), object(), object()
