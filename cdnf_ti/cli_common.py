"""Command-line helpers shared by every subcommand: model options, argparse types, exit codes.

The option scheme: one meaning per name in every subcommand (the README's "Options" table).

==========================  =======================================================================
``INPUT ...``               video file, image folder, ``.npy`` array, ``stim:NAME?...`` (positional)
``--model M[,M..]|all``     the models to run (``--models`` is the same option)
``--param [M.]NAME=VALUE``  set a model parameter (repeatable; :mod:`cdnf_ti.param_options`);
                            ``experiment sweep`` spells a grid the same way (``NAME=V1,V2``)
``--epsilon X``             shortcut for ``--param cdnf.epsilon=X``; an error unless cdnf runs
``--backend``, ``--arch``,  the engine: Taichi kernels or the NumPy float64 reference, the Taichi
``--compiler``              arch, the kernel compiler
``--fps N``                 frame rate of file inputs (frames/s); wherever files are read
``--color-order bgr|rgb``   channel order of colour ``.npy`` arrays; wherever files are read
``--rain [on|off|both]``    synthetic rain: the flag or ``on`` rainy only, ``both`` clean and rainy,
                            ``off`` clean only (``none``/``only``: deprecated, with a note)
``--rain-drops N``          droplets per frame (``--drops``: deprecated); ``--rain-seed S`` the rain's seed
``--stimulus-seed S``       the seed of generated stimuli (incoherent dots, grid stimuli)
``--seed S``                the default of every seed the command has (rain and stimulus)
``--skip-missing``          batch runs: leave out labelled clips that have no video (default: an error)
``--out DIR``               always a folder (created; default ``cdnf_out`` or a folder inside it,
                            ``cdnf_experiments/<name>`` for experiments); a movie path only where the
                            command makes one file (``render --out FILE.mp4`` with one movie,
                            ``generate --out FILE.avi``, ``live --record FILE.mp4``)
``--workers N``, ``--scheduler ADDRESS``  parallel batch runs
``--no-progress``           hide progress bars
``--sensor-size WxH``, ``--bin-ms``, ``--event-threshold C``  how event recordings are binned and scaled
                            (:func:`add_event_options`): ``run``, ``dataset``, ``table2``, ``sweep``,
                            ``render``, ``events``
``--record FILE.mp4``, ``--jsonl``, ``--udp``  the live loop's outputs (``cdnf_ti.live``)
==========================  =======================================================================

Each command adds the options it has with the helpers here (:func:`add_model_options`,
:func:`add_param_options`, :func:`add_input_options`, :func:`add_rain_options`,
:func:`add_seed_options`, :func:`add_output_option`, :func:`add_event_options`) and reads them back
with :func:`params_from_args`, :func:`rain_conditions`, :func:`rain_seed_of`,
:func:`stimulus_seed_of` and :func:`event_options_of`, so that a name has one meaning and one help text everywhere.

A leaf module: ``cdnf_ti.run`` (the entry point) and the subcommand modules
(``demo``, ``generate``, ``render``, ``experiments.cli``, ``bench.cli``) import it;
it imports none of them.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Sequence

from .errors import UserError
from .events.binning import DEFAULT_EVENT_THRESHOLD, DEFAULT_MAX_GAP_S, DEFAULT_MAX_SPAN_S
from .events.readers import parse_sensor_size
from .limits import MAX_DROPS
from .models import MODELS, get_model_class
from .param_options import model_params
from .taichi_runtime import COMPILERS, check_arch, select_compiler, set_compile_notices

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class ArgumentParser(argparse.ArgumentParser):
    """The subcommands' parser: a bad option is one ``error:`` line and exit 2, like every user error.

    (argparse's own ``error`` prints the whole usage block first.) ``--rain`` followed by anything
    but one of its words (``on``, ``off``, ``both`` and the deprecated ones) is the flag: ``--rain
    clip.mp4`` is rain on ``clip.mp4``, not a bad ``--rain`` value (:func:`rain_flag_argv`).
    ``--no-progress`` also silences the compile notices (:func:`~cdnf_ti.taichi_runtime.set_compile_notices`).
    """

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        if args is not None:
            args = rain_flag_argv(list(args))
        ns, rest = super().parse_known_args(args, namespace)
        if getattr(ns, "no_progress", False):
            set_compile_notices(False)  # --no-progress: no "compiling kernels" lines either (workers inherit it)
        return ns, rest


def note(text: str) -> None:
    """Print ``note: <text>`` on stderr (one line)."""
    print(f"note: {text}", file=sys.stderr)


class _DeprecatedAlias(argparse.Action):
    """An old spelling of an option: stores like the new one and prints a one-line ``note:``."""

    def __init__(self, option_strings, dest, new_name: str = "", **kw):
        self.new_name = new_name
        super().__init__(option_strings, dest, **kw)

    def __call__(self, parser, namespace, values, option_string=None):
        note(f"{option_string} is deprecated; use {self.new_name}")
        setattr(namespace, self.dest, values)


def add_deprecated_alias(ap: argparse.ArgumentParser, old: str, new: str, dest: str, **kw) -> None:
    """Accept ``old`` as a hidden, deprecated spelling of option ``new`` (same ``dest``, a ``note:`` when used)."""
    ap.add_argument(old, dest=dest, action=_DeprecatedAlias, new_name=new, help=argparse.SUPPRESS,
                    default=argparse.SUPPRESS, **kw)


# --- files read: --fps, --color-order -------------------------------------------------------------

def add_input_options(ap: argparse.ArgumentParser) -> None:
    """``--fps`` and ``--color-order``: how file inputs are read (every command that reads files)."""
    ap.add_argument("--fps", type=positive_float, default=None,
                    help="frame rate of the file inputs in frames/s (default: a video's own rate; 30 for image "
                         "folders and .npy arrays, which carry none)")
    ap.add_argument("--color-order", choices=("bgr", "rgb"), default="bgr",
                    help="channel order of colour .npy arrays (default: %(default)s, as OpenCV; arrays "
                         "from imageio, PIL or matplotlib are rgb). Video files and images are decoded by "
                         "OpenCV and are always right")


# --- event recordings: --sensor-size, --bin-ms, --event-threshold ------------------------------------

def sensor_size_arg(text: str) -> tuple[int, int]:
    """argparse type: ``WxH`` (width x height in pixels)."""
    try:
        return parse_sensor_size(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_event_options(ap: argparse.ArgumentParser) -> None:
    """``--sensor-size``, ``--bin-ms``, ``--event-threshold``: how an event recording becomes model input;
    ``--max-gap-s``, ``--max-span-s``: the limits past which a timestamp is taken as corrupt.

    Read them back with :func:`event_options_of`.
    """
    ap.add_argument("--sensor-size", type=sensor_size_arg, default=None, metavar="WxH",
                    help="sensor size of event recordings (default: the file's header; else the smallest that "
                         "holds every event)")
    ap.add_argument("--bin-ms", type=positive_float, default=None, metavar="MS",
                    help="events are binned into frames this long, ms, for every model (default: each model's own "
                         "width, its time step where it has one, e.g. event_looming's dt of 10 ms; else 1000/30 = "
                         "33.333..., one 30 fps frame)")
    ap.add_argument("--event-threshold", type=positive_float, default=DEFAULT_EVENT_THRESHOLD, metavar="C",
                    help="the sensor's log-contrast threshold C: n events at a pixel in a bin give the models a "
                         "contrast min(1, n C) (default: %(default)s); for 'events VIDEO' the emulated threshold")
    ap.add_argument("--max-gap-s", type=positive_float, default=DEFAULT_MAX_GAP_S, metavar="S",
                    help="an event more than S seconds after every event before it is a corrupt timestamp, an "
                         "error (default: %(default)g; raise it for a recording with long pauses)")
    ap.add_argument("--max-span-s", type=positive_float, default=DEFAULT_MAX_SPAN_S, metavar="S",
                    help="an event more than S seconds after the recording's start is a corrupt timestamp, an "
                         "error (default: %(default)g, 24 h)")


def event_options_of(args: argparse.Namespace) -> dict:
    """``{"sensor_size", "bin_ms", "event_threshold", "max_gap_s", "max_span_s"}`` from the options of
    :func:`add_event_options` (the defaults where the command has none; ``bin_ms`` None: not given, each
    model bins at its own width, :func:`cdnf_ti.models.base.bin_ms_for`)."""
    bin_ms = getattr(args, "bin_ms", None)
    return {"sensor_size": getattr(args, "sensor_size", None),
            "bin_ms": None if bin_ms is None else float(bin_ms),
            "event_threshold": float(getattr(args, "event_threshold", DEFAULT_EVENT_THRESHOLD)),
            "max_gap_s": float(getattr(args, "max_gap_s", DEFAULT_MAX_GAP_S)),
            "max_span_s": float(getattr(args, "max_span_s", DEFAULT_MAX_SPAN_S))}


def given_event_options(args: argparse.Namespace) -> list[str]:
    """The event options given other than their defaults (``["--bin-ms"]``), for a ``note:`` when no
    input is an event recording."""
    opts = event_options_of(args)
    return [o for o, changed in (("--sensor-size", opts["sensor_size"] is not None),
                                 ("--bin-ms", opts["bin_ms"] is not None),
                                 ("--event-threshold", opts["event_threshold"] != DEFAULT_EVENT_THRESHOLD),
                                 ("--max-gap-s", opts["max_gap_s"] != DEFAULT_MAX_GAP_S),
                                 ("--max-span-s", opts["max_span_s"] != DEFAULT_MAX_SPAN_S))
            if changed]


# --- rain: --rain [on|off|both], --rain-drops, --rain-seed ----------------------------------------

#: The words of ``--rain``: ``off`` clean input only, ``on`` rainy input only, ``both`` each input twice.
RAIN_WORDS = ("on", "off", "both")
#: Deprecated words (the batch commands' former ``--rain none|only|both``) and what they mean now.
OLD_RAIN_WORDS = {"none": "off", "only": "on"}
#: ``--rain`` word -> the conditions it runs, in order.
RAIN_CONDITIONS = {"off": ("clean",), "on": ("rain",), "both": ("clean", "rain")}
#: ``--rain`` word -> the batch engines' ``rain=`` argument (:data:`cdnf_ti.experiments.layout.RAIN_CHOICES`).
RAIN_ENGINE_WORD = {"off": "none", "on": "only", "both": "both"}


def rain_word(text: str) -> str:
    """argparse type of ``--rain``: ``on``, ``off`` or ``both`` (``none``/``only``: deprecated, with a note)."""
    w = str(text).strip().lower()
    if w in RAIN_WORDS:
        return w
    if w in OLD_RAIN_WORDS:
        note(f"--rain {w} is deprecated; use --rain {OLD_RAIN_WORDS[w]}")
        return OLD_RAIN_WORDS[w]
    raise argparse.ArgumentTypeError(f"expected one of {', '.join(RAIN_WORDS)}, got {text!r}")


def rain_flag_argv(argv: list[str]) -> list[str]:
    """``--rain`` followed by an input (or an option, or nothing) becomes ``--rain=on``, so the next word
    stays an input.

    The next word is taken as ``--rain``'s value, so that a wrong one (``--rain maybe``) is reported with
    the valid words, unless it looks like an input: an existing path, a ``stim:`` spec, or a name with a
    dot or a path separator (``clip.mp4``, ``videos/``).
    """
    words = set(RAIN_WORDS) | set(OLD_RAIN_WORDS)
    out = []
    for i, a in enumerate(argv):
        if a == "--":
            return out + argv[i:]
        if a == "--rain" and (i + 1 >= len(argv) or (argv[i + 1].strip().lower() not in words
                                                      and _looks_like_input(argv[i + 1]))):
            out.append("--rain=on")
        else:
            out.append(a)
    return out


def _looks_like_input(word: str) -> bool:
    """Whether a word after ``--rain`` is an input or an option rather than a (wrong) rain word."""
    return (word.startswith("-") or word.startswith("stim:") or any(c in word for c in "./\\")
            or Path(word).exists())


def add_rain_options(ap: argparse.ArgumentParser, default: str = "off", flag: bool = True,
                     what: str = "each input", drops: bool = True) -> None:
    """``--rain [on|off|both]``, ``--rain-drops N`` and (deprecated) ``--drops``.

    Parameters
    ----------
    default : {"off", "on", "both"}
        What the command does without ``--rain``.
    flag : bool
        Whether ``--rain`` is offered (``rain`` always rains: it has only the drop count).
    drops : bool
        Whether ``--rain-drops`` is offered (the command can set the droplet count).
    """
    if flag:
        ap.add_argument("--rain", nargs="?", const="on", default=default, type=rain_word, metavar="on|off|both",
                        help=f"synthetic rain (paper, Sec. III-A-2) on {what}, in memory: --rain or --rain on = "
                             f"rainy only, --rain both = clean and rainy, --rain off = clean only "
                             f"(default: {default})")
    if drops:
        ap.add_argument("--rain-drops", type=drops_arg, default=None, metavar="N",
                        help="rain droplets per frame (default: 500 per 426x240, scaled by the frame area)")
        add_deprecated_alias(ap, "--drops", "--rain-drops", "rain_drops", type=drops_arg)


def rain_conditions(args: argparse.Namespace) -> tuple[str, ...]:
    """The conditions ``--rain`` asks for: ``("clean",)``, ``("rain",)`` or ``("clean", "rain")``."""
    return RAIN_CONDITIONS[getattr(args, "rain", "off") or "off"]


def note_unused_rain_options(args: argparse.Namespace) -> None:
    """A ``note:`` when ``--rain-drops`` or ``--rain-seed`` is given but no rain is made (``--rain off``)."""
    if getattr(args, "rain", "off") != "off":
        return
    unused = [o for o, d in (("--rain-drops", "rain_drops"), ("--rain-seed", "rain_seed"))
              if getattr(args, d, None) is not None]
    if unused:
        verb = "change" if len(unused) > 1 else "changes"
        note(f"{' and '.join(unused)} {verb} nothing without --rain (on or both)")


# --- seeds: --seed (the default of every seed), --rain-seed, --stimulus-seed ------------------------

def add_seed_options(ap: argparse.ArgumentParser, rain: bool = False, stimulus: bool = False) -> None:
    """``--seed S`` (default 0) and the seeds it is the default of: ``--rain-seed``, ``--stimulus-seed``.

    Read them back with :func:`rain_seed_of` and :func:`stimulus_seed_of`.
    """
    kinds = [k for k, on in (("--rain-seed", rain), ("--stimulus-seed", stimulus)) if on]
    ap.add_argument("--seed", type=seed_arg, default=0, metavar="S",
                    help=f"the default of every seed of the command ({', '.join(kinds) or 'none'}; default 0)")
    if rain:
        ap.add_argument("--rain-seed", type=seed_arg, default=None, metavar="S",
                        help="seed of the synthetic rain (default: --seed)")
    if stimulus:
        ap.add_argument("--stimulus-seed", type=seed_arg, default=None, metavar="S",
                        help="seed of the generated stimuli: the incoherent displacement (default: --seed)")


def rain_seed_of(args: argparse.Namespace) -> int:
    """``--rain-seed``, else ``--seed``, else 0."""
    v = getattr(args, "rain_seed", None)
    return int(v if v is not None else (getattr(args, "seed", 0) or 0))


def stimulus_seed_of(args: argparse.Namespace) -> int:
    """``--stimulus-seed``, else ``--seed``, else 0."""
    v = getattr(args, "stimulus_seed", None)
    return int(v if v is not None else (getattr(args, "seed", 0) or 0))


# --- output: --out ------------------------------------------------------------------------------------

#: Where results go without ``--out`` (``run``; the other commands use a folder inside it).
DEFAULT_OUT = "cdnf_out"


def add_output_option(ap: argparse.ArgumentParser, default: str | None = DEFAULT_OUT, movie: bool = False) -> None:
    """``--out DIR``: the folder results go to (created; ``default`` without it).

    With ``movie=True`` (``render``) ``--out`` may also name the movie file itself (``.mp4``/``.avi``)
    when the command makes one file.
    """
    text = ("output folder (created)" if not movie else
            "output folder (created), or the movie file (.mp4/.avi) when the command makes one movie")
    ap.add_argument("--out", default=default, required=default is None, metavar="DIR",
                    help=text + (f" (default: {default})" if default else ""))


def add_model_options(ap: argparse.ArgumentParser, default_models: str = "cdnf") -> None:
    """Options shared by every command that runs models."""
    ap.add_argument("--model", "--models", dest="models", default=default_models,
                    help="model name(s), comma separated (default: %(default)s); 'all' for every model")
    ap.add_argument("--backend", default="taichi", choices=("taichi", "numpy"),
                    help="taichi kernels (default) or the NumPy float64 reference")
    ap.add_argument("--arch", default="cpu", choices=("cpu", "cuda", "vulkan", "gpu"),
                    help="Taichi architecture (default: cpu)")
    ap.add_argument("--compiler", choices=COMPILERS, default=None, action=_CompilerAction,
                    help="kernel compiler (default: $CDNF_TI_COMPILER, else the fastest installed)")


def add_param_options(ap: argparse.ArgumentParser, epsilon: bool = True) -> None:
    """``--param [MODEL.]NAME=VALUE`` (repeatable) and the ``--epsilon`` shortcut.

    Read them back with :func:`params_from_args`.
    """
    ap.add_argument("--param", action="append", default=[], metavar="[MODEL.]NAME=VALUE",
                    help="set a model parameter (repeatable): NAME=VALUE for every selected model that has it, "
                         "MODEL.NAME=VALUE for one model")
    if epsilon:
        ap.add_argument("--epsilon", type=finite_float, default=None,
                        help="C-DNF alert margin (default 0.006); shortcut for --param cdnf.epsilon=X")


def params_from_args(args: argparse.Namespace, models: Sequence[str]) -> dict:
    """``{model: params or None}`` from the options of :func:`add_param_options` (one-line errors)."""
    return model_params(models, getattr(args, "param", []) or [], getattr(args, "epsilon", None))


class _CompilerAction(argparse.Action):
    """``--compiler``: names the process's kernel compiler (and its workers') as soon as it is parsed."""

    def __call__(self, parser, namespace, values, option_string=None):
        select_compiler(values)  # UserError (one line, exit 2) when it is not installed
        setattr(namespace, self.dest, values)


def check_model_options(args: argparse.Namespace) -> None:
    """Check the options of :func:`add_model_options` before any work: the Taichi arch must exist here.

    Raises
    ------
    BackendUnavailableError
        ``--arch`` names a GPU backend this machine does not have (one line, exit 2).
    """
    if getattr(args, "backend", "taichi") == "taichi":
        check_arch(getattr(args, "arch", "cpu"))


def finite_float(text: str) -> float:
    """argparse type: a finite number (rejects inf and nan)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value


def non_negative_float(text: str) -> float:
    """argparse type: a finite number >= 0."""
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value


def drops_arg(text: str) -> int:
    """argparse type: a rain droplet count per frame (0 .. :data:`cdnf_ti.limits.MAX_DROPS`)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if not math.isfinite(value) or value != int(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {text!r}")
    if value > MAX_DROPS:
        raise argparse.ArgumentTypeError(f"{text} droplets per frame is too many (at most {MAX_DROPS:,})")
    return int(value)


def seed_arg(text: str) -> int:
    """argparse type for seeds: a non-negative integer."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer, got {text!r}")
    return value


def parse_models(spec: str) -> list[str]:
    """``"cdnf,lgmd2"`` -> registry names; ``"all"`` -> every registered model."""
    if spec.strip().lower() == "all":
        return list(MODELS)
    names = [s.strip() for s in spec.split(",") if s.strip()]
    if not names:
        raise UserError(f"--model names no model: got {spec!r}")
    try:
        return list(dict.fromkeys(get_model_class(n).name for n in names))
    except ValueError as e:
        raise UserError(f"--model: {e}") from None


def unique_names(paths: Sequence[str], names: Sequence[str]) -> list[str]:
    """Output names for inputs, made distinct: inputs sharing a name (``A/clip.mp4``, ``B/clip.mp4``)
    are named after their folder too (``A_clip``, ``B_clip``), then numbered (``clip-2``) if need be.

    Names are compared case-insensitively (case-insensitive file systems).
    """
    def counts(xs):
        c: dict[str, int] = {}
        for x in xs:
            c[x.lower()] = c.get(x.lower(), 0) + 1
        return c

    c = counts(names)
    out = []
    for p, n in zip(paths, names):
        parent = Path(str(p)).parent.name if c[n.lower()] > 1 else ""
        out.append(f"{parent}_{n}" if parent else n)
    seen: dict[str, int] = {}
    final = []
    for n in out:
        k = n.lower()
        seen[k] = seen.get(k, 0) + 1
        final.append(n if seen[k] == 1 else f"{n}-{seen[k]}")
    while len({n.lower() for n in final}) < len(final):  # a numbered name met a real one: number again
        final = [n if i == [m.lower() for m in final].index(n.lower()) else f"{n}-{i + 1}"
                 for i, n in enumerate(final)]
    return final
