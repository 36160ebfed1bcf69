"""Loading and validating the irdic configuration.

The schema (``irdic/schemas/config.schema.yaml``) lists every key with its
default, unit and meaning. :func:`validate_config` checks a configuration
against it, fills in the defaults and raises :class:`~irdic.errors.ConfigError`
with the dotted key that is wrong (``calibration.polarty: unknown key ...``).
The Snakemake workflow, the CLI and the Python API all call this one function.
"""

from __future__ import annotations

import copy
import functools
import math
import os
import re
from importlib import resources
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import yaml

from .errors import ConfigError

__all__ = ["SCHEMA_PATH", "load_schema", "validate_config", "load_config", "command_line_values", "non_defaults",
           "load_yaml", "check_folders", "input_folder", "check_finite", "METHOD_SECTIONS", "MAX_ALIAS_NODES",
           "MAX_REPR"]

SCHEMA_PATH = Path(str(resources.files("irdic") / "schemas" / "config.schema.yaml"))

#: Most YAML nodes that aliases (``*name``) may add to a configuration once
#: expanded. A real configuration repeats a setup or two (a few hundred
#: nodes); nested aliases ("billion laughs") reach billions from one kilobyte.
MAX_ALIAS_NODES = 10_000

#: Longest repr of a value quoted in a configuration error message (chars).
MAX_REPR = 300


def _clip(text: str, limit: int = MAX_REPR) -> str:
    """``text`` cut to ``limit`` characters, saying how much was left out."""
    if len(text) <= limit:
        return text
    return text[:limit] + f"... ({len(text) - limit} more characters)"


class _AliasBomb(yaml.YAMLError):
    """Raised by :class:`_ConfigLoader`; turned into a ConfigError naming the file."""


class _DuplicateKey(yaml.YAMLError):
    """Raised by :class:`_ConfigLoader` for a key given twice in one mapping."""


class _ConfigLoader(yaml.SafeLoader):
    """A SafeLoader that refuses duplicate keys, recursive aliases and alias expansion bombs.

    PyYAML keeps the last of two equal keys in a mapping: an experiment block
    copied with its name left unchanged would replace the first one without a
    word. Each mapping is therefore checked for keys that compare equal (after
    construction: ``1`` and ``1.0`` are the same marker ID); merge keys
    (``<<: *base``) may be overridden, as YAML intends.

    Aliases share the anchored node, so loading itself stays cheap; the cost
    comes later, when validation walks (and error messages print) the
    expanded document. Each alias is therefore charged the number of nodes
    its anchor expands to, and loading stops once the total passes
    :data:`MAX_ALIAS_NODES`.
    """

    def __init__(self, stream):
        super().__init__(stream)
        self._expanded: dict[int, int] = {}
        self._open_anchors: set[str] = set()
        self._alias_nodes = 0

    def _size(self, node: yaml.Node) -> int:
        # Memoised per node: anchored subtrees are shared, so this is linear in
        # the written document even when the expansion is exponential.
        key = id(node)
        if key not in self._expanded:
            if isinstance(node, yaml.SequenceNode):
                n = 1 + sum(self._size(c) for c in node.value)
            elif isinstance(node, yaml.MappingNode):
                n = 1 + sum(self._size(k) + self._size(v) for k, v in node.value)
            else:
                n = 1
            self._expanded[key] = n
        return self._expanded[key]

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                try:
                    first = seen.get(key)
                except TypeError:  # an unhashable key: the constructor refuses it with its own message
                    continue
                seen.setdefault(key, line)
                if first is not None:
                    raise _DuplicateKey(f"line {line}: key {_clip(repr(key))} is given twice in the same mapping "
                                        f"(first at line {first}); the second would silently replace the first, "
                                        "rename or remove one")
        return super().construct_mapping(node, deep)

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            line = event.start_mark.line + 1
            if event.anchor in self._open_anchors:
                raise _AliasBomb(f"line {line}: alias *{event.anchor} refers to a value that contains it (recursive alias)")
            if event.anchor in self.anchors:
                self._alias_nodes += self._size(self.anchors[event.anchor])
                if self._alias_nodes > MAX_ALIAS_NODES:
                    raise _AliasBomb(
                        f"line {line}: alias *{event.anchor} makes the aliases expand to more than "
                        f"{MAX_ALIAS_NODES} values; write the repeated values out instead of nesting aliases"
                    )
            return super().compose_node(parent, index)
        anchor = None
        for kind in (yaml.ScalarEvent, yaml.SequenceStartEvent, yaml.MappingStartEvent):
            if self.check_event(kind):
                anchor = self.peek_event().anchor
        if anchor is None:
            return super().compose_node(parent, index)
        self._open_anchors.add(anchor)
        try:
            return super().compose_node(parent, index)
        finally:
            self._open_anchors.discard(anchor)


def load_schema() -> dict:
    """The configuration schema as a dict (a fresh copy: callers may change it)."""
    return copy.deepcopy(_parsed_schema())


@functools.lru_cache(maxsize=1)
def _parsed_schema() -> dict:
    # Parsing the YAML costs ~60 ms; each stage entry and config check asks for it.
    with open(SCHEMA_PATH, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def _fill_defaults(validator_class):
    """A validator class that also writes ``default`` values into the instance.

    Objects that are absent but have a default (usually ``{}``) are created
    first, so nested defaults are filled as well.
    """
    validate_properties = validator_class.VALIDATORS["properties"]

    def set_defaults(validator, properties, instance, schema):
        if isinstance(instance, dict):
            for name, sub in properties.items():
                if "default" in sub and name not in instance:
                    instance[name] = copy.deepcopy(sub["default"])
        yield from validate_properties(validator, properties, instance, schema)

    return jsonschema.validators.extend(validator_class, {"properties": set_defaults})


def _where(error: jsonschema.ValidationError) -> str:
    parts = [str(p) for p in error.absolute_path]
    return ".".join(parts) if parts else "(top level)"


def _alternative(schema: dict) -> str:
    """One alternative of a ``oneOf`` in words: ``'auto'``, ``null``, ``a number > 0``."""
    if "const" in schema:
        return repr(schema["const"])
    if schema.get("type") == "null":
        return "null"
    bound = next((f" {op} {schema[k]}" for k, op in (("exclusiveMinimum", ">"), ("minimum", ">="))
                  if k in schema), "")
    return f"a {schema.get('type', 'value')}{bound}"


def _message(error: jsonschema.ValidationError) -> str:
    where = _where(error)
    if error.validator == "additionalProperties" and isinstance(error.instance, dict):
        allowed = sorted(error.schema.get("properties", {}))
        # Keys may be numbers or dates in YAML; sort by repr so mixed types compare.
        extra = sorted((str(e) for e in set(error.instance) - set(allowed)), key=str)
        if allowed:
            keys = _clip(", ".join(repr(e) for e in extra))
            prefix = f"{where}." if where != "(top level)" else ""
            return f"{prefix}{_clip(extra[0]) if len(extra) == 1 else '{' + keys + '}'}: unknown key; allowed here: {', '.join(allowed)}"
    if "propertyNames" in error.relative_schema_path:
        return (
            f"{where}: name {_clip(repr(error.instance))} is not allowed; {where} names become folder names under the "
            "results folder and may contain only letters, digits, '_', '-' and '.', not starting with '.'"
        )
    if error.validator == "required":
        return f"{where}: {error.message}"
    if error.validator == "anyOf":
        alts = [repr(a["const"]) if "const" in a else f"a {a.get('type', 'value')}" for a in error.validator_value]
        return f"{where}: {_clip(repr(error.instance))} is not {' or '.join(alts)}"
    if error.validator == "oneOf":
        return f"{where}: {_clip(repr(error.instance))} is not {' or '.join(_alternative(s) for s in error.validator_value)}"
    if error.validator == "enum":
        return f"{where}: {_clip(repr(error.instance))} is not one of {', '.join(map(repr, error.validator_value))}"
    return f"{where}: {_clip(error.message)}"


def _non_finite(value: Any, where: str) -> tuple[str, float] | None:
    """``(dotted key, value)`` of the first NaN or infinite number in ``value`` (a loaded configuration), or None.

    JSON Schema's ``type: number`` admits NaN and infinity, and every
    comparison with NaN is false, so ``minimum`` does not catch it either.
    """
    if isinstance(value, float) and not np.isfinite(value):
        return where, value
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, (list, tuple)):
        items = enumerate(value)
    else:
        return None
    for k, v in items:
        found = _non_finite(v, f"{where}.{k}" if where else str(k))
        if found is not None:
            return found
    return None


def check_finite(config: Any, prefix: str = "") -> None:
    """Raise :class:`ConfigError` naming the key of a NaN or infinite number in ``config``."""
    found = _non_finite(config, prefix)
    if found is not None:
        raise ConfigError(f"{found[0] or '(top level)'}: {found[1]!r} is not a finite number; give a number (a lab "
                          "script that failed to estimate it may have written .nan or .inf)")


def _input_keys(config: dict) -> list[tuple[str, str]]:
    """``(dotted key, path)`` of every raw input the configuration names."""
    keys = []
    for name, s in config.get("setups", {}).items():
        keys += [(f"setups.{name}.{k}.path", s[k]["path"]) for k in ("markers", "target_image")]
    for name, e in config.get("experiments", {}).items():
        keys += [(f"experiments.{name}.{k}.path", e[k]["path"]) for k in ("dic", "ir", "machine") if e.get(k)]
    return keys


def input_folder(path: str | os.PathLike) -> tuple[Path, bool]:
    """An input path with links resolved (a glob as its folder), and whether it names a whole folder."""
    parts = Path(path).parts
    wild = [i for i, part in enumerate(parts) if any(ch in part for ch in "*?[")]
    if wild:
        return Path(os.path.realpath(Path(*parts[:wild[0]]) if wild[0] else ".")), True
    real = Path(os.path.realpath(path))
    return real, real.is_dir()


def _overlap(a: Path, b: Path) -> bool:
    return a == b or a in b.parents or b in a.parents


def check_folders(config: dict) -> None:
    """Refuse a results folder that overlaps a raw-data folder, before anything runs.

    irdic replaces what it writes under ``results``; a results folder inside
    an export folder would add its stores to the series it reads, and an
    export folder inside ``results`` could be replaced by a stage. Links are
    followed. A single input file only must not lie inside ``results``.

    Raises
    ------
    ConfigError
        Naming both keys and the resolved folders.
    """
    results = Path(os.path.realpath(config["results"]))
    demo = config.get("demo", {})
    demo_dir = Path(os.path.realpath(demo["outdir"])) if demo.get("enabled") else None
    if demo_dir is not None and _overlap(results, demo_dir):
        raise ConfigError(f"results: the results folder {config['results']} ({results}) and demo.outdir "
                          f"{demo['outdir']} ({demo_dir}) overlap; give them separate folders")
    for key, path in _input_keys(config):
        folder, whole = input_folder(path)
        if demo_dir is not None and (folder == demo_dir or demo_dir in folder.parents):
            continue  # written by the demo stage, checked against results above
        inside = results == folder or results in folder.parents
        if inside or (whole and folder in results.parents):
            where = "lies inside" if inside else "contains"
            raise ConfigError(f"{key}: the input {path} ({folder}) {where} the results folder {config['results']} "
                              f"({results}); raw data and results must not overlap (irdic replaces what it "
                              "writes under results), move one of them")


def validate_config(config: dict, *, base_dir: str | os.PathLike | None = None) -> dict:
    """Check ``config`` against the schema and fill in defaults (in place).

    Parameters
    ----------
    config : dict
        The configuration (as loaded from YAML).
    base_dir : path-like, optional
        Unused for now; relative paths are taken relative to the working
        directory, as Snakemake does.

    Returns
    -------
    dict
        ``config`` itself, completed with defaults.

    Raises
    ------
    ConfigError
        Naming the dotted key and what was expected; cross-references (an
        experiment's ``setup``) are checked too.
    """
    if not isinstance(config, dict):
        raise ConfigError(f"the configuration must be a mapping of keys to values, got {type(config).__name__}")
    check_finite(config)
    schema = load_schema()
    cls = _fill_defaults(jsonschema.Draft202012Validator)
    validator = cls(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: (len(e.absolute_path), list(map(str, e.absolute_path))))
    if errors:
        msgs = [_message(e) for e in errors[:5]]
        more = f" (and {len(errors) - 5} more)" if len(errors) > 5 else ""
        raise ConfigError("invalid configuration: " + "; ".join(msgs) + more)
    setups = config["setups"]
    for name, exp in config["experiments"].items():
        if exp["setup"] not in setups:
            raise ConfigError(
                f"experiments.{name}.setup: setup {exp['setup']!r} is not defined; defined setups: {', '.join(setups)}"
            )
        for kind in ("dic", "ir"):
            src = exp[kind]
            if src["time_source"] == "frame_rate" and src["frame_rate"] is None:
                raise ConfigError(f"experiments.{name}.{kind}.frame_rate: required when time_source is frame_rate")
        if exp["dic"]["format"] == "table":
            cols = exp["dic"]["columns"]
            missing = [r for r in ("x", "y", "z") if r not in cols]
            if missing:
                raise ConfigError(
                    f"experiments.{name}.dic.columns: format table needs the column names of {', '.join(missing)}"
                )
        _check_material(name, exp.get("material"))
        machine = exp.get("machine")
        if machine is not None:
            bad = [k for k in machine["columns"] if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", k)]
            if bad:
                raise ConfigError(f"experiments.{name}.machine.columns: signal name {bad[0]!r} must be an "
                                  "identifier such as force or angle (it names the signal machine_<name>)")
            sep = machine["sep"]
            if sep is not None and (len(sep) != 1 or sep in "\r\n\"'#"):
                raise ConfigError(f"experiments.{name}.machine.sep: expected one character such as ',', ';' "
                                  f"or '\\t', got {sep!r}")
            if sep == "," and machine["decimal"] == ",":
                raise ConfigError(f"experiments.{name}.machine.decimal: ',' is impossible with sep ','")
    for name, setup in setups.items():
        seeds = setup.get("seeds", {})
        if seeds and len(seeds) < 6:
            raise ConfigError(f"setups.{name}.seeds: give at least 6 markers (got {len(seeds)}) or none")
        ids: dict = {}
        for key in seeds:
            try:
                marker = int(key)
            except (TypeError, ValueError, OverflowError):
                raise ConfigError(f"setups.{name}.seeds: marker ID {key!r} is not an integer") from None
            if marker in ids:
                raise ConfigError(f"setups.{name}.seeds: marker ID {marker} is given twice ({ids[marker]!r} and "
                                  f"{key!r}); each marker has one seed position")
            ids[marker] = key
    check_folders(config)
    return config


def _check_material(name: str, material) -> None:
    """The checks of an experiment's ``material`` block that the schema cannot express."""
    if material is None:
        return
    cooling = material.get("cooling")
    if material["loss_time_constant"] == "auto" and cooling is None:
        raise ConfigError(f"experiments.{name}.material.loss_time_constant: auto needs material.cooling: [t0, t1], "
                          "a window of DIC times (s) without heat sources, e.g. a natural cooling after unloading")
    if cooling is not None and not cooling[1] > cooling[0]:
        raise ConfigError(f"experiments.{name}.material.cooling: expected [t0, t1] with t1 > t0 (s), got {cooling}")


def load_yaml(path: str | os.PathLike) -> Any:
    """A YAML configuration file as loaded data, not yet validated.

    Raises
    ------
    ConfigError
        The file is missing, not UTF-8, not YAML, holds a key twice in one
        mapping (both lines named) or aliases that expand without bound.
    """
    p = Path(path)
    try:
        with open(p, encoding="utf-8") as fh:
            data = yaml.load(fh, Loader=_ConfigLoader)
    except FileNotFoundError:
        raise ConfigError(f"{p}: configuration file not found") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{p}: not a UTF-8 text file (byte {exc.start} cannot be decoded)") from None
    except (_AliasBomb, _DuplicateKey) as exc:
        raise ConfigError(f"{p}, {exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML ({_clip(str(exc), 2 * MAX_REPR)})") from None
    except RecursionError:
        raise ConfigError(f"{p}: not valid YAML (nested too deeply)") from None
    return data


def load_config(path: str | os.PathLike) -> dict:
    """Read a YAML configuration file and validate it (see :func:`validate_config`)."""
    p = Path(path)
    data = load_yaml(p)
    if data is None:
        raise ConfigError(f"{p}: configuration file is empty")
    try:
        return validate_config(data)
    except ConfigError as exc:
        raise ConfigError(f"{p}: {exc}") from None


def parse_setting(text: str) -> tuple[list[str], Any]:
    """``"section.key=value"`` (``irdic --set``) as ``(["section", "key"], value)``.

    The value is read as YAML, as it would be in ``config.yaml``: ``2.5`` is
    a number, ``gcv`` a string, ``[1, 2]`` a list, ``null`` None.

    Raises
    ------
    ConfigError
        No ``=``, or no dotted key before it.
    """
    key, sep, value = text.partition("=")
    parts = [p for p in key.strip().split(".")]
    if not sep or len(parts) < 2 or not all(parts):
        raise ConfigError(f"--set {text!r}: expected section.key=value, such as interpolation.c_space=2.5")
    try:
        parsed = yaml.safe_load(value) if value.strip() else None
    except yaml.YAMLError:
        parsed = value  # free text (a path with a colon, a quote): the schema checks it as a string
    return parts, parsed


def validate_section(section: str, values: dict, *, schema_node: str | None = None) -> dict:
    """Check the keys of one configuration section against the schema, with defaults filled in.

    Parameters
    ----------
    section : str
        Name used in the messages (``"interpolation"``, ``"ir"``).
    values : dict
        The section's keys as the user gave them.
    schema_node : str, optional
        The schema property or definition that describes the section
        (default ``section``; ``"ir_source"`` for an experiment's ``ir``).

    Returns
    -------
    dict
        A completed copy of ``values``.

    Raises
    ------
    ConfigError
        The messages of :func:`validate_config`, each naming ``section.key``.
    """
    schema = load_schema()
    name = schema_node or section
    node = schema["properties"].get(name) or schema["$defs"].get(name)
    if node is None:
        raise KeyError(name)
    cls = _fill_defaults(jsonschema.Draft202012Validator)
    data = copy.deepcopy(values)
    check_finite(data, section)
    errors = list(cls({"$defs": schema["$defs"], **node}).iter_errors(data))
    if errors:
        msgs = []
        for e in sorted(errors, key=lambda e: list(map(str, e.absolute_path)))[:5]:
            e.path.appendleft(section)
            msgs.append(_message(e))
        raise ConfigError("invalid configuration: " + "; ".join(msgs))
    return data


def _types(node: dict, defs: dict) -> set[str]:
    """JSON types a schema node allows (through ``$ref``, ``anyOf`` and ``oneOf``)."""
    if "$ref" in node:
        node = {**defs[node["$ref"].rsplit("/", 1)[-1]], **{k: v for k, v in node.items() if k != "$ref"}}
    t = node.get("type")
    out = {t} if isinstance(t, str) else set(t or ())
    for sub in node.get("anyOf", []) + node.get("oneOf", []):
        out |= _types(sub, defs)
    return out


def _child(node: dict, key, defs: dict) -> dict | None:
    """The schema node of ``key`` inside the object node ``node``."""
    if "$ref" in node:
        node = defs[node["$ref"].rsplit("/", 1)[-1]]
    sub = node.get("properties", {}).get(key)
    if sub is None and isinstance(node.get("additionalProperties"), dict):
        sub = node["additionalProperties"]
    return sub


def _typed(text: str, types: set[str]):
    """``text`` as the number, boolean or null the schema wants, or ``text`` when it is none of them."""
    low = text.strip().lower()
    if "null" in types and low in ("null", "~", "none", ""):
        return None
    if "boolean" in types and low in ("true", "false"):
        return low == "true"
    for kind, parse in (("integer", int), ("number", float)):
        if kind in types:
            try:
                value = parse(text)
            except ValueError:
                continue
            if kind == "number" and not math.isfinite(value):
                continue  # NaN or inf: the schema's message for a string is clearer than a silent NaN
            return value
    return text


def command_line_values(config: dict, given: dict) -> dict:
    """``config`` with the strings of ``given`` typed as the schema wants them (in place).

    Snakemake's ``--config section="{key: 8}"`` hands nested values over as
    strings. Where the schema wants a number (or a boolean or null) and a
    value given on the command line is a string that reads as one, the value
    in ``config`` becomes that number; every other value, and everything from
    configuration files, is left for :func:`validate_config` to check.

    Parameters
    ----------
    config : dict
        The merged configuration (files and command line).
    given : dict
        The values given on the command line, nested as in ``config``.
    """
    schema = load_schema()
    defs = schema["$defs"]

    def walk(cfg, cli, node):
        for key, value in cli.items():
            sub = _child(node, key, defs) if node else None
            if sub is None or not isinstance(cfg, dict) or key not in cfg:
                continue
            if isinstance(value, dict) and isinstance(cfg[key], dict):
                walk(cfg[key], value, sub)
            elif isinstance(value, str) and isinstance(cfg[key], str) and "string" not in _types(sub, defs):
                cfg[key] = _typed(cfg[key], _types(sub, defs))

    if isinstance(config, dict) and isinstance(given, dict):
        walk(config, given, schema)
    return config


#: sections of the method's parameters (the others name inputs and outputs)
METHOD_SECTIONS = ("demo", "calibration", "interpolation", "fields", "execution", "export")


def non_defaults(config: dict) -> dict:
    """``{"section.key": value}`` of the method's parameters that differ from the schema's defaults.

    Parameters
    ----------
    config : dict
        A validated configuration (:func:`validate_config`).
    """
    out = {}

    def walk(prefix, given, default):
        for key in sorted(given, key=str):
            value, ref = given[key], default.get(key) if isinstance(default, dict) else None
            if isinstance(value, dict) and isinstance(ref, dict):
                walk(f"{prefix}{key}.", value, ref)
            elif value != ref:
                out[f"{prefix}{key}"] = value

    for section in METHOD_SECTIONS:
        if isinstance(config.get(section), dict):
            walk(f"{section}.", config[section], validate_section(section, {}))
    return out


def get(config: dict, dotted: str, default: Any = None) -> Any:
    """``config["a"]["b"]`` for ``"a.b"``, or ``default``."""
    cur: Any = config
    for part in dotted.split("."):
        if not isinstance(cur, dict) or part not in cur:
            return default
        cur = cur[part]
    return cur
