"""Configuration errors a person can act on, for every TOML loader (service and scenario files).

msgspec already names the field (`Invalid enum value 'imm-cv' - at `$.tracker.motion.model``).
`convert` turns that into one line that also says which file and line, the value given, the
values allowed (a Literal's choices) and the nearest known key for a typo (difflib):

    configs/x.toml:21: tracker.motion.model = 'imm-cv': not one of 'ca', 'ct', 'cv', 'imm_cv'; did you mean 'imm_cv'?
    configs/x.toml:3: unknown key 'namspace'; did you mean 'namespace'? (keys here: tracker, namespace, ...)

The line is found by a small scan of `[table]`, `[[array]]` headers and `key =` lines; it is
omitted when the scan cannot place the field (inline tables, multi-line values).
"""

from __future__ import annotations

import difflib
import re
from typing import Any, TypeVar

import msgspec

from fusion.errors import ConfigError

T = TypeVar("T")
Path_ = list[str | int]

_AT = re.compile(r"^(?P<msg>.*?)(?: - at (?P<key>`key` in )?`(?P<path>\$[^`]*)`)?$", re.S)
_SEG = re.compile(r"\.([^.\[]+)|\[(\d+)\]")
_MISSING = object()


def decode_toml(data: bytes | str, *, source: str) -> Any:
    """The TOML document as plain data; ConfigError naming the file and line when malformed."""
    try:
        return msgspec.toml.decode(data)
    except msgspec.DecodeError as e:
        m = re.search(r"at line (\d+)", str(e))
        where = f"{source}:{m.group(1)}" if m else source
        raise ConfigError(f"{where}: malformed TOML: {e}") from None


def convert(raw: Any, typ: type[T], *, source: str, text: bytes | str = b"", prefix: Path_ | None = None) -> T:
    """msgspec.convert(raw, typ), or ConfigError with one actionable line (see the module doc).

    prefix: where `raw` sits inside the file (["service"] for a scenario file's [service] table)."""
    try:
        return msgspec.convert(raw, type=typ)
    except msgspec.ValidationError as e:
        raise ConfigError(explain(e, typ, raw, source=source, text=text, prefix=prefix or [])) from None


def explain(err: msgspec.ValidationError, typ: type, raw: Any, *, source: str, text: bytes | str = b"",
            prefix: Path_ | None = None) -> str:
    """One line: file[:line]: field: what is wrong (and what would be right)."""
    prefix = prefix or []
    m = _AT.match(str(err))
    msg, at = (m.group("msg"), m.group("path") or "$") if m else (str(err), "$")
    if m and m.group("key"):  # a mapping's key is wrong, e.g. a sensor id: say so
        msg = f"a key: {msg}"
    path: Path_ = [s if s else int(i) for s, i in _SEG.findall(at[1:])]
    node = _type_at(msgspec.inspect.type_info(typ), path)
    value = _value_at(raw, path)
    field_path = path
    if u := re.match(r"Object contains unknown field `(.+)`$", msg):
        name = u.group(1)
        field_path = [*path, name]
        keys = [f.encode_name for f in node.fields] if isinstance(node, msgspec.inspect.StructType) else []
        what = f"unknown key '{name}'" + _did_you_mean(name, keys)
        if keys:
            what += f" (keys here: {', '.join(keys)})"
    elif r := re.match(r"Object missing required field `(.+)`$", msg):
        what = f"required key '{r.group(1)}' is missing"
    elif msg.startswith("Invalid value") and path and (tags := _tags_at(typ, path)):
        what = f"{_show(value)} is not one of {', '.join(repr(t) for t in tags)}" + _did_you_mean(str(value), tags)
    elif msg.startswith("Invalid enum value") and isinstance(node, msgspec.inspect.LiteralType):
        allowed = [str(v) for v in node.values]
        what = f"{_show(value)} is not one of {', '.join(repr(v) for v in node.values)}" + _did_you_mean(
            str(value), allowed)
    else:
        what = msg.replace("`", "")
        if value is not _MISSING and ", got" not in what and not isinstance(value, dict | list):
            what += f", got {_show(value)}"
    return _line(source, text, prefix + field_path, _render(prefix + field_path), what)


def _line(source: str, text: bytes | str, path: Path_, field: str, what: str) -> str:
    n = line_of(text, path) if text else None
    where = f"{source}:{n}" if n else source
    return f"{where}: {field}: {what}" if field else f"{where}: {what}"


def _did_you_mean(name: str, options: list[str]) -> str:
    close = difflib.get_close_matches(name, options, n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


def _show(value: Any) -> str:
    return "nothing" if value is _MISSING else repr(value)


def _render(path: Path_) -> str:
    out = ""
    for s in path:
        out += f"[{s}]" if isinstance(s, int) else (f".{s}" if out else s)
    return out


def _type_at(info: Any, path: Path_, *, follow_last: bool = True) -> Any:
    """The msgspec.inspect type at `path` (None where the path leaves the schema); a union at
    the end of the path is returned as it is when follow_last is False."""
    for seg in path:
        while isinstance(info, msgspec.inspect.UnionType):  # e.g. `X | None`: follow the structured member
            info = next((t for t in info.types if not isinstance(t, msgspec.inspect.NoneType)), None)
        if isinstance(seg, int) and isinstance(info, msgspec.inspect.ListType | msgspec.inspect.SetType):
            info = info.item_type
        elif isinstance(seg, str) and isinstance(info, msgspec.inspect.StructType):
            info = next((f.type for f in info.fields if f.encode_name == seg), None)
        elif isinstance(seg, str) and isinstance(info, msgspec.inspect.DictType):
            info = info.value_type
        else:
            return None
    while follow_last and isinstance(info, msgspec.inspect.UnionType):
        info = next((t for t in info.types if not isinstance(t, msgspec.inspect.NoneType)), None)
    return info


def _tags_at(typ: type, path: Path_) -> list[str]:
    """The tags of the tagged union whose tag field `path` names (e.g. a sensor's `kind`)."""
    parent = _type_at(msgspec.inspect.type_info(typ), path[:-1], follow_last=False)
    if not isinstance(parent, msgspec.inspect.UnionType):
        return []
    return [str(t.tag) for t in parent.types
            if isinstance(t, msgspec.inspect.StructType) and t.tag_field == path[-1] and t.tag is not None]


def _value_at(raw: Any, path: Path_) -> Any:
    for seg in path:
        try:
            raw = raw[seg]
        except (KeyError, IndexError, TypeError):
            return _MISSING
    return raw


_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-\".]+)\s*=")


def line_of(text: bytes | str, path: Path_) -> int | None:
    """1-based line of the first header or key that `path` names or lies under, or None."""
    if not path:  # the document itself
        return None
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    want = [str(s) for s in path]
    table: list[str] = []
    arrays: dict[tuple[str, ...], int] = {}
    for n, line in enumerate(text.splitlines(), 1):
        h = _HEADER.match(line)
        if h:
            names = [p.strip().strip('"') for p in h.group(2).split(".")]
            table = []
            for i, name in enumerate(names):
                table.append(name)
                key = tuple(names[: i + 1])
                if h.group(1) == "[[" and i == len(names) - 1:
                    arrays[key] = arrays.get(key, -1) + 1
                if key in arrays:
                    table.append(str(arrays[key]))
            here = table
        else:
            k = _KEY.match(line)
            if not k:
                continue
            here = table + [p.strip().strip('"') for p in k.group(1).split(".")]
        if here[: len(want)] == want or (h is None and want[: len(here)] == here):
            return n  # the header or key itself, or a key whose value holds the target
    return None
