"""``--param [MODEL.]NAME=VALUE``: setting any model parameter from the command line.

One meaning in every command that runs models (``run``, ``dataset``, ``render``, ``live``,
the ``experiment`` runners): the parameter ``NAME`` of the selected models takes ``VALUE``.

* ``NAME=VALUE`` sets ``NAME`` in every selected model that has a parameter of that name,
  and is an error when none has.
* ``MODEL.NAME=VALUE`` sets it in that model only (an error when that model is not selected
  or has no such parameter).
* ``--epsilon X`` is a shortcut for ``--param cdnf.epsilon=X``, an error unless C-DNF runs.
* ``experiment sweep`` spells a *grid* the same way: ``NAME=V1,V2`` or ``NAME=START:STOP:N``.

Values are converted to the parameter's type (bool, int, float or str) and checked by the
model's own parameter validation; any problem is one ``error:`` line.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

from .errors import UserError
from .models import get_model_class


def field_kind(params_type: type, name: str) -> str:
    """The type of parameter ``name`` of a parameter dataclass: ``"bool"``, ``"int"``, ``"float"`` or ``"str"``.

    Raises
    ------
    UserError
        ``name`` is not a parameter of ``params_type`` (the message lists the known ones).
    """
    fields = {f.name: f for f in dataclasses.fields(params_type)}
    if name not in fields:
        tunable = ", ".join(f.name for f in dataclasses.fields(params_type))
        raise UserError(f"--param {name}: unknown parameter of {params_type.__name__}; known: {tunable}")
    t = fields[name].type
    t = t if isinstance(t, str) else getattr(t, "__name__", str(t))
    for kind in ("bool", "int", "float", "str"):
        if t.replace(" ", "").split("|")[0] == kind:
            return kind
    return "float"


def convert_value(kind: str, name: str, text: str) -> Any:
    """``text`` as a value of ``kind`` (see :func:`field_kind`); a bad value is a :class:`UserError`."""
    s = text.strip()
    if s == "":
        raise UserError(f"--param {name}: empty value")
    if kind == "bool":
        low = s.lower()
        if low in ("1", "true", "yes", "on"):
            return True
        if low in ("0", "false", "no", "off"):
            return False
        raise UserError(f"--param {name}: {s!r} is not a boolean (true/false)")
    if kind == "str":
        return s
    try:
        v = float(s)
    except ValueError:
        raise UserError(f"--param {name}: {s!r} is not a number") from None
    if not math.isfinite(v):
        raise UserError(f"--param {name}: {s!r} is not a finite number")
    if kind == "int":
        if not v.is_integer():
            raise UserError(f"--param {name}: {s!r} is not a whole number ({name} is an integer)")
        return int(v)
    return v


def _has_param(params_type: type, name: str) -> bool:
    return dataclasses.is_dataclass(params_type) and name in {f.name for f in dataclasses.fields(params_type)}


def model_params(models: Sequence[str], specs: Sequence[str], epsilon: float | None = None) -> dict[str, Any]:
    """The parameter object of each selected model, from ``--param`` and ``--epsilon``.

    Parameters
    ----------
    models : sequence of str
        Registry names of the selected models.
    specs : sequence of str
        The ``--param`` values, ``[MODEL.]NAME=VALUE`` each (applied in order; a later one wins).
    epsilon : float, optional
        ``--epsilon``: C-DNF's alert margin.

    Returns
    -------
    dict
        ``{model: params or None}``; ``None`` where the model keeps its defaults.

    Raises
    ------
    UserError
        A malformed spec, a parameter no selected model has, a model not selected, a value of
        the wrong type, or values the model's validation rejects.
    """
    classes = {m: get_model_class(m) for m in models}
    changes: dict[str, dict[str, Any]] = {m: {} for m in models}
    if epsilon is not None:
        specs = [f"cdnf.epsilon={epsilon!r}", *specs]
        if "cdnf" not in classes:
            raise UserError(f"--epsilon applies to the cdnf model only, which is not among --model "
                            f"{','.join(models)} (use --param NAME=VALUE for the others)")
    for spec in specs:
        lhs, eq, value = spec.partition("=")
        lhs = lhs.strip()
        if not eq or not lhs:
            raise UserError(f"--param {spec!r}: expected NAME=VALUE or MODEL.NAME=VALUE")
        target, dot, name = lhs.rpartition(".")
        if dot:
            try:
                target = get_model_class(target).name
            except ValueError as e:
                raise UserError(f"--param {spec}: {e}") from None
            if target not in classes:
                raise UserError(f"--param {spec}: model {target!r} is not among --model {','.join(models)}")
            targets = [target]
            field_kind(classes[target].params_type, name)  # unknown name: one line listing the known ones
        else:
            targets = [m for m, cls in classes.items() if _has_param(cls.params_type, name)]
            if not targets:
                raise UserError(f"--param {spec}: no selected model ({', '.join(models)}) has a parameter {name!r}")
        for m in targets:
            changes[m][name] = convert_value(field_kind(classes[m].params_type, name), name, value)
    out: dict[str, Any] = {}
    for m, kw in changes.items():
        if not kw:
            out[m] = None
            continue
        try:
            out[m] = classes[m].params_type(**kw)
        except (TypeError, ValueError) as e:
            raise UserError(f"--param ({m}): {e}") from None
    return out
