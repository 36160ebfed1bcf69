"""Stage parameters: the defaults of the configuration schema, and nothing else.

Every default lives once, in ``irdic/schemas/config.schema.yaml``. A stage
called with some of its parameters (the command line, a test, a script of
one's own) gets the others from there, so the stores written from the
workflow and from Python agree.
"""

from __future__ import annotations

import copy
from functools import lru_cache
from typing import Mapping

from .config import check_finite, load_schema
from .errors import ConfigError

__all__ = ["schema_defaults", "settings"]


@lru_cache(maxsize=None)
def _properties(section: str) -> dict:
    schema = load_schema()
    node = schema["properties"].get(section) or schema["$defs"].get(section)
    if node is None:
        raise KeyError(section)
    return node["properties"]


def schema_defaults(section: str) -> dict:
    """The ``default`` of every key of a configuration section that has one.

    Parameters
    ----------
    section : str
        A top-level section (``"interpolation"``, ``"fields"``, ``"export"``,
        ``"calibration"``, ``"demo"``) or a definition of the schema
        (``"ir_source"``, ``"dic_source"``, ``"machine_source"``).

    Returns
    -------
    dict
        A fresh copy (callers may change it).
    """
    return {k: copy.deepcopy(v["default"]) for k, v in _properties(section).items() if "default" in v}


def settings(section: str, params: Mapping, *, drop: tuple[str, ...] = ()) -> dict:
    """``params`` completed with the schema defaults of ``section``.

    Raises
    ------
    ConfigError
        ``params`` holds a key the section does not know (a typo must not
        fall back to a default silently); the message lists the known keys.
        A number is NaN or infinite (``section.key`` is named).
    """
    known = set(_properties(section)) - set(drop)
    unknown = sorted(set(params) - known)
    if unknown:
        raise ConfigError(f"{section}: unknown parameter(s) {', '.join(unknown)}; "
                          f"expected {', '.join(sorted(known))}")
    out = {k: v for k, v in schema_defaults(section).items() if k not in drop}
    check_finite(dict(params), section)
    out.update(params)
    return out
