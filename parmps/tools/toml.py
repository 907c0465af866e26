"""A small TOML writer for validated cases (tomllib only reads)."""

import json
import math


def _scalar(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        if math.isnan(value):
            return "nan"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_scalar(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_key(k)} = {_scalar(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {type(value).__name__} as TOML")


def _key(key):
    return key if key.replace("_", "").replace("-", "").isalnum() else json.dumps(key)


def dumps(document):
    """Write a nested dict (tables, arrays of tables, scalars) as TOML text."""
    lines = []
    for key, value in document.items():
        if not isinstance(value, dict) and not _is_table_array(value):
            lines.append(f"{_key(key)} = {_scalar(value)}")
    for key, value in document.items():
        if isinstance(value, dict):
            lines.append(f"\n[{_key(key)}]")
            lines.extend(f"{_key(k)} = {_scalar(v)}" for k, v in value.items())
        elif _is_table_array(value):
            for item in value:
                lines.append(f"\n[[{_key(key)}]]")
                lines.extend(f"{_key(k)} = {_scalar(v)}" for k, v in item.items())
    return "\n".join(lines).lstrip("\n") + "\n"


def _is_table_array(value):
    return isinstance(value, list) and value and all(isinstance(v, dict) for v in value)
