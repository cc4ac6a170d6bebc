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
``--rain``                  add synthetic rain; ``--rain both`` runs clean and rainy, ``--rain off``
                            clean only (the batch commands take the same three words)
``--rain-drops N``          droplets per frame; ``--rain-seed S`` the rain's seed
``--stimulus-seed S``       the seed of generated stimuli (incoherent dots, grid stimuli)
``--seed S``                the default of every seed the command has (rain and stimulus)
``--out DIR``               always a folder (created); a movie path only where the command makes
                            one file (``render --out FILE.mp4``, ``live --record FILE.mp4``)
``--workers N``, ``--scheduler ADDRESS``  parallel batch runs
``--no-progress``           hide progress bars
==========================  =======================================================================

A leaf module: ``cdnf_ti.run`` (the entry point) and the subcommand modules
(``demo``, ``generate``, ``render``, ``experiments.cli``, ``bench.cli``) import it;
it imports none of them.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Sequence

from .errors import UserError
from .limits import MAX_DROPS
from .models import MODELS, get_model_class
from .taichi_runtime import COMPILERS, check_arch, select_compiler

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class ArgumentParser(argparse.ArgumentParser):
    """The subcommands' parser: a bad option is one ``error:`` line and exit 2, like every user error.

    (argparse's own ``error`` prints the whole usage block first.)
    """

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"error: {message} (see {self.prog} --help)\n")


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
    from .param_options import model_params

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
