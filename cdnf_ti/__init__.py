"""cdnf_ti: C-DNF looming perception on video, with Taichi kernels.

Quick start::

    from cdnf_ti import CDNF, open_source, iter_grey
    src = open_source("clip.mp4")
    trace = CDNF().run(iter_grey(src))
    print(trace.first_alert, trace.output.max())
"""
import os as _os

_os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")  # keep CLI output clean
_os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # FFmpeg's own messages on bad files; we report them
_os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")

# Installed, the top-level folders kernels/, stimuli/ and bench/ of the repository become
# cdnf_ti.kernels, cdnf_ti.stimuli and cdnf_ti.bench (setuptools package-dir). When cdnf_ti is
# imported straight from a source checkout (e.g. `python -m pytest` in the repository root puts
# the checkout first on sys.path), let the same names resolve to those folders.
_here = _os.path.dirname(_os.path.abspath(__file__))
_root = _os.path.dirname(_here)
if not _os.path.isdir(_os.path.join(_here, "kernels")) and _os.path.isfile(
    _os.path.join(_root, "kernels", "__init__.py")
):
    __path__.append(_root)  # type: ignore[name-defined]  # noqa: F821

from ._version import __version__
from .backends import ENGINE as _ENGINE
from .errors import InputError
from .frames import FrameSource, iter_grey, open_source, to_grey
from .models import MODELS, Model, StepResult, Trace, create_model, get_model_class, register_model
from .params import CDNFParams

Model.engine = _ENGINE  # the models' compiled backends come from the engine (cdnf_ti.backends)

#: Every registered model class and its parameters' class, by class name (``from cdnf_ti import OLGMD, LPLC2``).
_EXPORTS = {c.__name__: c for m in MODELS.values() for c in (m, m.params_type) if c is not object}
globals().update(_EXPORTS)

__all__ = ["CDNFParams", "Model", "StepResult", "Trace", "MODELS", "create_model", "get_model_class",
           "register_model", "InputError", "FrameSource", "open_source", "iter_grey", "to_grey", "__version__"]
__all__ += sorted(set(_EXPORTS) - set(__all__))
